"""Training-side tools (torch): turn datasets into ikid model files. Not part of the wheel."""
