"""`agp.Gradient.predict` equals the Rust planner's prediction (the gradient rebuilt from the
published grids, `AffordanceGradient::predict` at `aim_point_at`) within 1e-6, on the same
learned AG file: the grids written by `agp-py-reference grids`, the predictions printed by
`agp-py-reference predict`."""

import json
import math

from conftest import run_reference

from agp import Gradient

TOLERANCE = 1e-6


def test_the_gradient_predicts_as_rust_within_1e_6(ag_file, tmp_path):
    grids = tmp_path / "grids.bin"
    run_reference("grids", str(ag_file), str(grids))
    reference = json.loads(run_reference("predict", str(ag_file)))
    ag = Gradient.from_file(str(grids))
    assert ag.alphas_deg == reference["alphas_deg"]
    compared = predicted = 0
    for row in reference["rows"]:
        aim = ag.aim_point(row["contact_deg"])
        if row["aim_mm"] is None:
            assert aim is None, row
            continue
        assert aim is not None, row
        assert math.hypot(aim[0] * 1e3 - row["aim_mm"][0], aim[1] * 1e3 - row["aim_mm"][1]) < TOLERANCE, row
        p = ag.prediction(row["contact_deg"], row["alpha_deg"])
        want = row["prediction"]
        compared += 1
        if want is None:
            assert p is None, row
            continue
        assert p is not None, row
        predicted += 1
        got = ag.predict(row["contact_deg"], row["alpha_deg"])
        assert got == (p.dx_mm, p.dy_mm, p.dtheta_deg, p.spread_mm)
        for key in ("dx_mm", "dy_mm", "dtheta_deg", "spread_mm", "rotation_spread_deg", "confidence"):
            assert abs(getattr(p, key) - want[key]) < TOLERANCE, (key, row, p)
    # The triangle's gradient answers most of the 48 rays x 13 alphas.
    assert compared > 300 and predicted > 300, (compared, predicted)
