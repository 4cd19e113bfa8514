"""01 — Stand and reach: load a problem file, solve it, read the result, write and verify it.

TALOS stands with both feet fixed on flat ground and reaches a point with its right gripper.
Run: python examples/01_stand_and_reach.py [OUT_DIR]
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

import posturegen as pg
from posturegen.verify import verify_file

HERE = Path(__file__).resolve().parent


def main(out: Path) -> pg.Result:
    problem = pg.load_problem(HERE / "problems" / "stand_reach.yaml")
    print(problem.summary())  # variables, constraint blocks and costs, before any solve

    result = pg.solve(problem)
    if not result.success:  # a failure says why: diagnose names what blocks it
        raise SystemExit(pg.diagnose(problem, result).diagnosis)

    print(f"solved in {result.iterations} iterations, {1e3 * result.solve_time_s:.1f} ms")
    print("base position [m]:", np.round(result.q[:3], 3))
    for contact, forces in result.forces.items():  # one entry per force-bearing point
        total = sum(f.force for f in forces)
        print(f"{contact}: {len(forces)} points, total force [N] {np.round(total, 1)}")
    tau_max = np.abs(result.torques).max()
    print(f"largest joint torque: {tau_max:.1f} N·m")

    # every success was already re-checked on Pinocchio; the file can be checked again later
    path = result.write(out / "posture.json")
    report = verify_file(path)  # posturegen verify FILE: Pinocchio and the meshes, no solver
    print(report.summary())
    return result


if __name__ == "__main__":
    out = Path(sys.argv[1]) if len(sys.argv) > 1 else Path("out/example01")
    main(out)
