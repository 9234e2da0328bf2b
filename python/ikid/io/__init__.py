"""File formats at ikid's boundaries (one module per format). Units convert here only:
TRC markers in millimetres, MOT angles in degrees; everything in memory is SI."""

from ikid.io.opensim import write_mot, write_sto, write_trc

__all__ = ["write_mot", "write_sto", "write_trc"]
