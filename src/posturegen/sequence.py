"""Contact sequences, by their name before the sub-packages (kept for user code; the module is
:mod:`posturegen.climb.sequence`). A re-export only: nothing in the package imports it."""

from .climb.sequence import SequenceReport, StageReport, run_sequence, stage_problem_dict

__all__ = ["SequenceReport", "StageReport", "run_sequence", "stage_problem_dict"]
