"""The exam of issue #28: ikid judged on wrist models it did not make.

Trials are simulated by OpenSim 4.6 from two published wrist models (``models.py``), with
our own motion generator (``motion.py``), three marker layouts and four artefacts
(``markers.py``); truth angles and torques come from the models themselves (``truth.py``).
ikid runs through its CLI as a lab would, biorbd's EKF and OpenSim's IK/ID as their users
would (``runs.py``), and ``__main__.py`` scores everything on the last 10 % of each trial and
writes ``docs/exam.md`` and ``target/exam.json``. Nothing here is ever trained or tuned on:
``tests/test_exam.py`` checks that training cannot reach these seeds or models.
"""
