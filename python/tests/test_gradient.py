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


def test_the_gradients_grids_are_views_over_the_memory_given_not_copies(ag_file, tmp_path):
    """What `agp.run` does with the loaned samples of `agp/grids`: the gradient's grids
    read the samples' memory in place, so a change there shows in the gradient's arrays."""
    import ctypes

    import numpy as np

    from agp.payloads import GradientGrid

    grids = tmp_path / "grids.bin"
    run_reference("grids", str(ag_file), str(grids))
    data = grids.read_bytes()
    size = ctypes.sizeof(GradientGrid)
    samples = [(ctypes.c_uint8 * size).from_buffer_copy(data[k * size : (k + 1) * size]) for k in range(len(data) // size)]
    ag = Gradient.from_buffers(samples)
    layer = ag.layers[0]
    for kind, grid in layer.grids.items():
        assert not grid.flags["OWNDATA"], kind
    # One cell of the first sample's grid, written in the sample, is read by the gradient.
    first = GradientGrid.from_buffer(samples[0])
    kind, alpha = first.header.kind, first.header.alpha_deg
    view = next(l for l in ag.layers if l.alpha_deg == alpha).grids[kind]
    first.cells[0] = 1234.5
    assert view[0] == np.float32(1234.5)
