"""03 — A failure and its diagnosis.

A target 1.5 m in front of TALOS cannot be reached with both feet on the ground. The solve
fails (``result.success`` is False, never a wrong posture); ``pg.diagnose`` relaxes the hard
rows by penalized slacks and says which ones had to give, by how much. Then a task of an
unknown type: bad input is one line naming the field and the fix.
Run: python examples/03_failure_and_diagnosis.py
"""

from __future__ import annotations

import copy
from pathlib import Path

import posturegen as pg
from posturegen.io.problem_file import read_yaml

HERE = Path(__file__).resolve().parent


def main() -> str:
    data = read_yaml(HERE / "problems" / "stand_reach.yaml")
    data["tasks"][0]["target"] = [1.5, -0.35, 0.9]  # [m]: out of reach
    problem = pg.problem_from_dict(data)
    result = pg.solve(problem)
    print("success:", result.success, "-", result.message)

    diagnosed = pg.diagnose(problem, result)
    print("diagnosis:", diagnosed.diagnosis)  # "target of task 0 is ... m beyond reach of ..."
    for cause in diagnosed.posture["diagnosis"]["causes"]:
        print(f"  {cause['kind']}: {cause['message']}")

    bad = copy.deepcopy(data)
    bad["tasks"][0]["type"] = "positon"
    try:
        pg.problem_from_dict(bad)
    except pg.InputError as error:
        print("input error:", error)  # tasks[0].type: unknown task type 'positon' (did you ...)
    return diagnosed.diagnosis


if __name__ == "__main__":
    main()
