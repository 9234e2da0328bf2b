"""Comparison studies: ikid beside its peers (biorbd's EKF, OpenSim, onnxruntime/torch) on the
same frames, each writing one page of docs/ (`make compare-ekf`, `compare-opensim`,
`compare-rates`, `bench-peers`). `common` holds what they and `benches/report.py` share."""
