"""The fault suite (`make faults`, part of `make test`): bad inputs fed to every reader, CLI
command, stream, tracker and C function, each a *probe* with its assertions (issue #22).

A probe passes when it ends with no traceback, crash or hang; with an error that names the
file (and the line or frame where that applies) or an output that is plausible or flagged;
with a non-zero exit where a trial was lost; and with every file that existed before
byte-for-byte unchanged unless the run succeeded. ``python -m faults`` (from ``tests/``)
builds the corpus in a temporary folder, runs every probe and prints one line per failing
probe, then the summary line::

    faults: probes=<n> passed=<n> silent=<n> partial_writes=<n> tracebacks=<n>

Modules: ``framework`` (probes, verdicts, the runner and its worker processes), ``corpus``
(the trial and the mutations), ``readers``, ``cli``, ``live`` (streams, the tracker, model
weights) and ``capi`` (libikid through ctypes): each has a ``probes(corpus)`` function.
"""
