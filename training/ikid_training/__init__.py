"""ikid's training pipeline: datasets into ikid model files, and the report that scores them.

A distribution of its own (``ikid-training``, ``pip install ./training`` from a checkout),
beside the runtime it depends on: the ``ikid`` wheel carries no training code and never
imports this package, except lazily for ``ikid train`` and the full ``ikid report``. The torch
side (``train``, ``export``, ``search``, ``models``, ``refine``) needs torch; ``data`` needs only
ikid and NumPy, ``report`` matplotlib. Scoring a model on recordings is the runtime's
(:mod:`ikid.evaluate`, :mod:`ikid.recordings`). Shipped configs live in ``configs/``
(:data:`CONFIG_DIR`; ``ikid train --config wrist-ik`` names one).
"""

from pathlib import Path

#: The shipped training configs (package data): ``<name>.toml``.
CONFIG_DIR = Path(__file__).with_name("configs")
