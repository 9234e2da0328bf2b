"""Training and evaluation: datasets into ikid model files, and the report that scores them.

Installed with the wheel but imported only on demand: ``import ikid`` never imports this
package. The torch side (``train``, ``export``, ``search``, ``models``) needs the training
extra (``pip install 'ikid[train]'``); ``data`` and ``evaluate`` need only ikid and NumPy.
Shipped configs live in ``configs/`` (``ikid train --config wrist-ik`` names one).
"""
