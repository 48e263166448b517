"""g2o / TORO / iSAM text graphs: round trips, conventions against gtsam's readers, malformed lines."""

from __future__ import annotations

import gtsam
import numpy as np
import pytest

from holoslam.errors import G2oFormatError, GraphError
from holoslam.graph.problem import problem_from_g2o
from holoslam.io.g2o import G2oGraph, TextNoise, parse_g2o, read_g2o
from holoslam.io.g2o_write import write_g2o
from holoslam.jobs import solve_g2o_file

SMALL = """# a tiny graph
VERTEX_SE2 0 0 0 0
VERTEX_SE2 1 1.0 0.1 0.05
VERTEX_SE2 2 2.1 0.0 1.6
VERTEX_XY 7 1.5 2.0
FIX 0
EDGE_SE2 0 1 1.0 0.0 0.0 500 10 0 400 0 1000
EDGE_SE2 1 2 1.0 0.0 1.57 500 0 0 500 0 1000
EDGE_SE2 2 0 -0.1 2.0 -1.57 100 0 0 100 0 300
EDGE_SE2_XY 0 7 1.5 2.0 100 5 80
EDGE_SE2_XY 2 7 1.9 0.4 100 0 100
"""


def test_round_trip_is_exact(tmp_path):
    g = parse_g2o(SMALL)
    assert g.vertex_ids.tolist() == [0, 1, 2] and g.point_ids.tolist() == [7] and g.fixed_ids.tolist() == [0]
    assert np.allclose(np.linalg.inv(g.edge_cov[0]), [[500, 10, 0], [10, 400, 0], [0, 0, 1000]])
    assert np.allclose(np.linalg.inv(g.landmark_cov[0]), [[100, 5], [5, 80]])
    path = write_g2o(g, tmp_path / "g.g2o")
    h = read_g2o(path)
    for name in (
        "vertex_ids",
        "vertex_poses",
        "point_ids",
        "point_positions",
        "edge_i",
        "edge_j",
        "edge_measured",
        "landmark_pose",
        "landmark_id",
        "landmark_measured",
        "fixed_ids",
    ):
        assert np.array_equal(getattr(g, name), getattr(h, name)), name
    assert np.allclose(h.edge_cov, g.edge_cov, rtol=1e-12)
    assert np.allclose(h.landmark_cov, g.landmark_cov, rtol=1e-12)


def test_edges_match_gtsam_readg2o(tmp_path):
    path = tmp_path / "p.g2o"
    path.write_text("\n".join(line for line in SMALL.splitlines() if "XY" not in line and "FIX" not in line))
    graph, values = gtsam.readG2o(str(path))
    g = read_g2o(path)
    for k in range(graph.size()):
        f = graph.at(k)
        assert np.allclose(f.noiseModel().covariance(), g.edge_cov[k], rtol=1e-9)
        assert np.allclose([f.measured().x(), f.measured().y(), f.measured().theta()], g.edge_measured[k])


@pytest.mark.parametrize(
    "line,expected_cov",
    [
        ("EDGE2 0 1 1 0 0 2 0 3 4 0 0", np.diag([2.0, 3.0, 4.0])),  # gtsam "GRAPH": TORO order as covariance
        ("ODOMETRY 0 1 1 0 0 2 0 0 3 0 4", np.diag([2.0, 3.0, 4.0])),  # gtsam "COV": g2o order as covariance
    ],
)
def test_text_noise_gtsam_auto_matches_load2d(tmp_path, line, expected_cov):
    path = tmp_path / "t.graph"
    path.write_text(line + "\n")
    graph, _ = gtsam.load2D(str(path))
    assert np.allclose(graph.at(0).noiseModel().covariance(), expected_cov)
    assert np.allclose(read_g2o(path).edge_cov[0], expected_cov)


def test_text_noise_explicit_conventions():
    line = "EDGE2 0 1 1 0 0 4 1 0 9 2 16\n"
    info = np.array([[4.0, 1, 0], [1, 9, 2], [0, 2, 16]])
    assert np.allclose(np.linalg.inv(parse_g2o(line, noise=TextNoise.INFORMATION).edge_cov[0]), info)
    assert np.allclose(parse_g2o(line, noise=TextNoise.COVARIANCE).edge_cov[0], info)
    R = np.array([[4.0, 1, 0], [0, 9, 2], [0, 0, 16]])
    assert np.allclose(np.linalg.inv(parse_g2o(line, noise=TextNoise.SQRT_INFORMATION).edge_cov[0]), R.T @ R)
    with pytest.raises(G2oFormatError, match="not positive definite"):  # TORO order: I_yy = 0 here
        parse_g2o(line, noise=TextNoise.TORO_INFORMATION)
    toro = parse_g2o("EDGE2 0 1 1 0 0 4 1 9 16 2 3\n", noise=TextNoise.TORO_INFORMATION).edge_cov[0]
    assert np.allclose(np.linalg.inv(toro), [[4, 1, 2], [1, 9, 3], [2, 3, 16]])
    with pytest.raises(G2oFormatError, match="explicit TextNoise"):
        parse_g2o(line)  # not a pattern gtsam's AUTO recognises


def test_landmark_lines_match_gtsam_load2d():
    path = gtsam.findExampleDataFile("victoria_park.txt")
    graph, _ = gtsam.load2D(path)
    g = read_g2o(path)
    from holoslam.graph.factors import bearing_range_from_xy

    b, r, cov = bearing_range_from_xy(g.landmark_measured[:60], g.landmark_cov[:60])
    k = 0
    for idx in range(60):
        f = graph.at(idx)
        if isinstance(f, gtsam.BearingRangeFactor2D):
            m = f.measured()
            assert np.isclose(m.bearing().theta(), b[k]) and np.isclose(m.range(), r[k])
            assert np.allclose(f.noiseModel().covariance(), cov[k], rtol=1e-9, atol=1e-15)
            k += 1
    assert k > 3


@pytest.mark.parametrize(
    "text,message",
    [
        ("EDGE_SE2 0 1 1 0 0 1 0 0 1 0\n", "needs 11 fields after the tag, found 10"),
        ("VERTEX_SE2 0 0 zero 0\n", "field 4 ('zero') is not a number"),
        ("VERTEX_SE2 0.5 0 0 0\n", "not a non-negative integer"),
        ("EDGE_SE2 0 1 1 0 0 1 0 0 -1 0 1\n", "not positive definite"),
        ("EDGE_SE2 0 1 1 0 nan 1 0 0 1 0 1\n", "not finite"),
    ],
)
def test_malformed_lines_say_file_line_and_what(text, message):
    with pytest.raises(G2oFormatError) as e:
        parse_g2o("VERTEX_SE2 5 0 0 0\n" + text, source="bad.g2o")
    assert "bad.g2o:2:" in str(e.value) and message in str(e.value)
    assert text.strip() in str(e.value)


def test_unknown_tags_are_reported_or_raise():
    text = "VERTEX_SE3:QUAT 0 0 0 0 0 0 0 1\nEQUIV 1 2\nVERTEX_SE2 0 0 0 0\n"
    g = parse_g2o(text)
    tags = {s.tag: s for s in g.skipped}
    assert tags["VERTEX_SE3:QUAT"].count == 1 and not tags["VERTEX_SE3:QUAT"].known
    assert tags["EQUIV"].known and tags["EQUIV"].first_line == 2
    with pytest.raises(G2oFormatError, match=r"<memory>:1: unknown tag 'VERTEX_SE3:QUAT'"):
        parse_g2o(text, strict=True)


@pytest.mark.parametrize(
    "text",
    [
        # the odometry chain places every pose first: the vectorised chain rule
        "ODOMETRY 0 1 1 0 0.5 1 0 0 1 0 1\nLANDMARK 1 9 2 0 0.4 0 0.4\nODOMETRY 1 2 1 0 0.5 1 0 0 1 0 1\n"
        "ODOMETRY 2 3 0.5 0.2 2.5 1 0 0 1 0 1\nLANDMARK 3 9 1 1 0.4 0 0.4\nODOMETRY 3 4 1 0 3.0 1 0 0 1 0 1\n",
        # a closure reaches pose 2 before its odometry edge: gtsam's line-by-line rule
        "ODOMETRY 0 1 1 0 0.5 1 0 0 1 0 1\nODOMETRY 0 2 1 1 0.2 1 0 0 1 0 1\nLANDMARK 2 9 2 0 0.4 0 0.4\n"
        "ODOMETRY 1 2 1 0 0.5 1 0 0 1 0 1\n",
    ],
)
def test_problem_from_g2o_initialises_like_load2d(tmp_path, text):
    path = tmp_path / "o.txt"
    path.write_text(text)
    _, values = gtsam.load2D(str(path))
    p = problem_from_g2o(read_g2o(path))
    for k, pid in enumerate(p.pose_ids):
        q = values.atPose2(int(pid))
        assert np.allclose(p.initial_wTa[k], [q.x(), q.y(), q.theta()])
    assert np.allclose(p.initial_landmarks["9"], values.atPoint2(gtsam.symbol("l", 9)))


def test_solve_g2o_file_matches_gtsam_and_writes(tmp_path):
    src = tmp_path / "in.g2o"
    # a noisy loop of 4 poses with a loop closure
    src.write_text(
        "VERTEX_SE2 0 0 0 0\nVERTEX_SE2 1 1.1 0.1 1.5\nVERTEX_SE2 2 1.0 1.2 3.0\nVERTEX_SE2 3 -0.1 0.9 -1.6\n"
        "EDGE_SE2 0 1 1 0 1.5708 100 0 0 100 0 400\nEDGE_SE2 1 2 1 0 1.5708 100 0 0 100 0 400\n"
        "EDGE_SE2 2 3 1 0 1.5708 100 0 0 100 0 400\nEDGE_SE2 3 0 1 0 1.5708 100 0 0 100 0 400\n"
    )
    summary, sol = solve_g2o_file(src, tmp_path / "out.g2o")
    graph, values = gtsam.readG2o(str(src))
    graph.add(
        gtsam.PriorFactorPose2(0, values.atPose2(0), gtsam.noiseModel.Diagonal.Sigmas([1e-4, 1e-4, 1e-5]))
    )
    ref = gtsam.LevenbergMarquardtOptimizer(graph, values, gtsam.LevenbergMarquardtParams()).optimize()
    assert abs(summary.final_error - graph.error(ref)) <= 1e-6 * graph.error(ref) + 1e-12
    out = read_g2o(tmp_path / "out.g2o")
    assert np.allclose(out.vertex_poses[1], [1, 0, np.pi / 2], atol=1e-3)
    assert out.fixed_ids.tolist() == [0] and out.edge_i.size == 4
    assert isinstance(out, G2oGraph)


def test_fast_tokeniser_matches_line_by_line_path():
    """The vectorised reader (np.loadtxt per tag, comments allowed) and the careful line-by-line reader (taken for
    lower-case tags) give identical graphs; mixed g2o/TORO edges keep file order."""
    body = SMALL.replace("# a tiny graph\n", "") + "EDGE2 1 0 -1.0 0.1 0.0 2 0 3 4 0 0\nEQUIV 1 2\n"
    fast = parse_g2o(body)
    slow = parse_g2o("# a comment line\nedge_se2 0 1 1 0 0 1 0 0 1 0 1\n" + body)  # lower case: careful path
    assert slow.edge_i.tolist()[0] == 0 and slow.edge_line[0] == 2
    slow = G2oGraph(
        **{
            **{k: getattr(slow, k) for k in G2oGraph.__dataclass_fields__},
            "edge_i": slow.edge_i[1:],
            "edge_j": slow.edge_j[1:],
            "edge_measured": slow.edge_measured[1:],
            "edge_cov": slow.edge_cov[1:],
            "edge_line": slow.edge_line[1:] - 1,
        }
    )
    commented = parse_g2o("# header\n" + body.replace("FIX 0", "FIX 0  # inline comment"))
    for name in (
        "vertex_ids",
        "vertex_poses",
        "point_ids",
        "edge_i",
        "edge_j",
        "edge_measured",
        "edge_cov",
        "landmark_id",
        "landmark_measured",
        "landmark_cov",
        "fixed_ids",
    ):
        assert np.array_equal(getattr(fast, name), getattr(slow, name)), name
        assert np.array_equal(getattr(fast, name), getattr(commented, name)), name
    assert np.array_equal(fast.edge_line + 1, slow.edge_line)
    assert np.array_equal(fast.edge_line + 1, commented.edge_line)
    assert fast.edge_i.tolist() == [0, 1, 2, 1]
    assert [s.tag for s in fast.skipped] == ["EQUIV"] == [s.tag for s in slow.skipped]
    with pytest.raises(G2oFormatError, match=r":3: EDGE_SE2 needs 11 fields"):
        parse_g2o("VERTEX_SE2 0 0 0 0\nVERTEX_SE2 1 0 0 0\nEDGE_SE2 0 1 1 0 0 1 0 0 1 0\n")
    with pytest.raises(G2oFormatError, match=r":2: field 4 \('x'\) is not a number"):
        parse_g2o("VERTEX_SE2 0 0 0 0\nVERTEX_SE2 1 0 x 0\n")


def test_closed_form_small_matrix_algebra_matches_numpy():
    from holoslam.graph.factors import noise_models
    from holoslam.graph.linalg import chol_upper, inv_sym

    rng = np.random.default_rng(1)
    for d in (2, 3):
        A = rng.normal(size=(200, d, d))
        C = A @ np.swapaxes(A, 1, 2) + 1e-3 * np.eye(d)
        assert np.allclose(inv_sym(C), np.linalg.inv(C), rtol=1e-8, atol=1e-10)
        R = chol_upper(C)
        assert np.allclose(R, np.swapaxes(np.linalg.cholesky(C), 1, 2), rtol=1e-10, atol=1e-12)
    C3 = np.concatenate([C, C[:5], np.diag([1.0, 4.0, 9.0])[None]])
    models, which = noise_models(C3)
    assert len(models) == 201 and which[200:205].tolist() == which[:5].tolist()
    for k in (0, 7, 200):
        assert np.allclose(models[which[k]].covariance(), C3[k], rtol=1e-8)
    assert np.allclose(models[which[-1]].sigmas(), [1.0, 2.0, 3.0])


def test_noise_models_are_shared_in_first_appearance_order():
    from holoslam.graph.factors import noise_models

    A = np.array([[2.0, 0.3, 0.1], [0.3, 1.0, 0.2], [0.1, 0.2, 0.5]])
    B, C = np.diag([1.0, 4.0, 9.0]), 2.0 * A
    models, which = noise_models(np.stack([B, A, B, C, A]))
    assert which.tolist() == [0, 1, 0, 2, 1] and len(models) == 3
    assert np.allclose(models[0].sigmas(), [1, 2, 3]) and isinstance(models[0], gtsam.noiseModel.Diagonal)
    assert np.allclose(models[1].covariance(), A) and np.allclose(models[2].covariance(), C)
    models, which = noise_models(np.stack([C, C, C]))
    assert len(models) == 1 and which.tolist() == [0, 0, 0]
    # -0.0 and 0.0 have equal fingerprints but are different bytes: still one model each, still correct
    D = B.copy()
    D[0, 1] = D[1, 0] = -0.0
    models, which = noise_models(np.stack([B, D, A]))
    assert which.tolist() == [0, 1, 2] and all(np.allclose(models[k].sigmas(), [1, 2, 3]) for k in (0, 1))


@pytest.mark.parametrize("mode", ["distinct", "diagonal", "mixed", "shared"])
def test_between_factors_keep_row_order_keys_and_noise(mode):
    from holoslam.graph.factors import between_factors

    rng = np.random.default_rng(3)
    m = 7
    A = rng.normal(size=(m, 3, 3))
    cov = A @ np.swapaxes(A, 1, 2) + 0.1 * np.eye(3)  # "distinct": one lazily made model per row
    if mode == "diagonal":
        cov = cov * np.eye(3)
    if mode == "mixed":
        cov[2] = np.diag([0.5, 0.25, 0.01])
    if mode == "shared":
        cov[5] = cov[1]
    iTj = rng.normal(size=(m, 3))
    g = between_factors(np.arange(m), np.arange(m) + 10, iTj, cov)
    assert g.size() == m
    for k in range(m):
        f = g.at(k)
        assert list(f.keys()) == [k, k + 10]
        p, t = f.measured(), iTj[k, 2]
        assert np.allclose(
            [p.x(), p.y(), p.theta()], [iTj[k, 0], iTj[k, 1], np.arctan2(np.sin(t), np.cos(t))]
        )
        assert np.allclose(f.noiseModel().covariance(), cov[k], rtol=1e-9)
        assert isinstance(f.noiseModel(), gtsam.noiseModel.Diagonal) == (
            mode == "diagonal" or k == 2 and mode == "mixed"
        )
    if mode == "shared":
        assert g.at(5).noiseModel().equals(g.at(1).noiseModel(), 0.0)
    with pytest.raises(GraphError, match="keys"):
        between_factors(np.arange(m), np.arange(m - 1), iTj, cov)


def test_problem_from_g2o_sparse_and_huge_ids():
    text = (
        "VERTEX_SE2 10 0 0 0\nVERTEX_SE2 3 1 0 0\nVERTEX_SE2 7 2 0 0\nFIX 7\n"
        "EDGE_SE2 10 3 1 0 0 1 0 0 1 0 1\nEDGE_SE2 3 7 1 0 0 1 0 0 1 0 1\n"
    )
    p = problem_from_g2o(parse_g2o(text))
    assert p.pose_ids.tolist() == [3, 7, 10]
    assert p.relative.i.tolist() == [2, 0] and p.relative.j.tolist() == [0, 1]
    assert np.allclose(p.initial_wTa[:, 0], [1, 2, 0]) and [q.i for q in p.priors] == [1]
    big = 10**12
    p = problem_from_g2o(
        parse_g2o(f"EDGE_SE2 {big} 5 1 0 0 1 0 0 1 0 1\nEDGE_SE2 5 {big + 1} 1 0 0 1 0 0 1 0 1\n")
    )
    assert p.pose_ids.tolist() == [5, big, big + 1]
    assert p.relative.i.tolist() == [1, 0] and p.relative.j.tolist() == [0, 2]
    g = G2oGraph(
        edge_i=[-4, 2], edge_j=[2, 9], edge_measured=np.zeros((2, 3)), edge_cov=np.tile(np.eye(3), (2, 1, 1))
    )
    p = problem_from_g2o(g)  # a graph built in memory may use negative ids
    assert (
        p.pose_ids.tolist() == [-4, 2, 9]
        and p.relative.i.tolist() == [0, 1]
        and p.relative.j.tolist() == [1, 2]
    )


def test_covariance_checks_name_the_bad_row():
    from holoslam.graph.problem import RelativePoseMeasurements

    cov = np.tile(np.eye(3), (4, 1, 1))
    cov[2] = np.diag([1.0, -1.0, 1.0])
    with pytest.raises(GraphError, match=r"cov_iTj\[2\] is not positive definite"):
        RelativePoseMeasurements(np.arange(4), np.arange(4) + 1, np.zeros((4, 3)), cov, "g2o")
    cov[2] = np.eye(3)
    cov[3, 0, 1] = 0.5
    with pytest.raises(GraphError, match=r"cov_iTj\[3\] is not symmetric"):
        RelativePoseMeasurements(np.arange(4), np.arange(4) + 1, np.zeros((4, 3)), cov, "g2o")
    cov[3] = np.eye(3)
    cov[1, 2, 2] = np.nan
    with pytest.raises(GraphError, match=r"cov_iTj\[1\] has non-finite"):
        RelativePoseMeasurements(np.arange(4), np.arange(4) + 1, np.zeros((4, 3)), cov, "g2o")


def test_kind_mask():
    from holoslam.graph.build import kind_mask

    kind = np.array(["odometry", "loop", "scan_match", "loop"], dtype=object)
    assert kind_mask(kind, ("loop",)).tolist() == [False, True, False, True]
    assert kind_mask(kind, ("none",)).tolist() == [False] * 4
    assert kind_mask(kind, ("loop", "odometry", "scan_match")).all()
    assert kind_mask(np.zeros(0, object), ("loop",)).shape == (0,)
