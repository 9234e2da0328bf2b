"""``python -m studies.exam``: runs the exam (see ``studies/exam/exam.py``)."""

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

from studies.exam.exam import main  # noqa: E402

main()
