import numpy as np
from mcap.reader import make_reader
from mcap_protobuf.decoder import DecoderFactory

from holoslam.io.results_mcap import ResultsScene, write_results_mcap
from holoslam.maps.grid import OccupancyGrid


def test_results_log_decodes_with_stock_foxglove_decoders(tmp_path):
    n = 50
    stamps = np.arange(n, dtype=np.int64) * 100_000_000 + 1_700_000_000_000_000_000
    wTb = np.column_stack([np.linspace(0, 4, n), np.zeros(n), np.linspace(-1, 1, n)])
    occ = np.full((20, 30), -1, np.int8)
    occ[5:15, 5:25] = 0
    occ[5, 5:25] = 100
    grid = OccupancyGrid(occ, 0.05, -1.0, -0.5)
    scene = ResultsScene(
        stamps_ns=stamps,
        wTb=wTb,
        dead_reckoning_wTb=wTb + 0.1,
        wTa=wTb[::10],
        grid=grid,
        object_ids=["O01", "O02"],
        w_objects=np.array([[1.0, 2.0, 0.8], [3.0, -1.0, 0.4]]),
        edges=[("topology", np.array([[[0, 0], [1, 1]], [[1, 1], [2, 0]]]))],
    )
    path = write_results_mcap(scene, tmp_path / "results.mcap", max_pose_messages=10)
    with path.open("rb") as f:
        msgs = list(make_reader(f, decoder_factories=[DecoderFactory()]).iter_decoded_messages())
    by_topic = {}
    for schema, channel, _message, decoded in msgs:
        by_topic.setdefault(channel.topic, []).append((schema.name, decoded))
    assert len(by_topic["/holoslam/pose"]) == 10
    ((name, traj),) = by_topic["/holoslam/trajectory"]
    assert name == "foxglove.PosesInFrame" and len(traj.poses) == n
    assert traj.poses[-1].position.x == 4.0
    ((name, g),) = by_topic["/holoslam/map"]
    assert name == "foxglove.Grid" and g.column_count == 30
    cells = np.frombuffer(g.data, np.uint8).reshape(20, 30)
    assert cells[0, 0] == 255 and cells[6, 6] == 0 and cells[5, 6] == 100
    ((name, objs),) = by_topic["/holoslam/objects"]
    assert [e.id for e in objs.entities] == ["object/O01", "object/O02"]
    assert objs.entities[1].cubes[0].pose.position.y == -1.0
    ((name, graph),) = by_topic["/holoslam/graph"]
    assert len(graph.entities[0].lines[0].points) == 4
