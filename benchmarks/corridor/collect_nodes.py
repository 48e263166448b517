"""Issue 25 diagnosis: run the front end (loop search off) on a log with ground truth and save, per node, the
pose chained through the anchors (local SLAM alone), the dead reckoning and the truth (a pickle for
corridor_legs.py). Usage: ``python benchmarks/corridor/collect_nodes.py LOG.mcap OUT.pkl``; the environment's
LOCAL / GRID / MATCH (JSON) override LocalSlamConfig / GridConfig / MatchConfig fields."""
import json
import os
import pickle
import sys
import time
from dataclasses import replace as _r

import numpy as np

sys.path.insert(0, str(__import__("pathlib").Path(__file__).resolve().parents[2]))
from holoslam import geometry as g  # noqa
from holoslam.io.mcap.reader import read_log
from holoslam.config import RunConfig
from holoslam.submaps import frontend as F
from holoslam.submaps.local_slam import LocalSlam
from holoslam.evaluate import truth_at

path, out = sys.argv[1], sys.argv[2]
log, rep = read_log(path)
cfg = RunConfig().frontend
cfg = _r(cfg, loops=_r(cfg.loops, every_nodes=1000000, global_per_node=0, global_per_node_lost=0))
lo = json.loads(os.environ.get("LOCAL", "{}"))
ma = json.loads(os.environ.get("MATCH", "{}"))
gr = json.loads(os.environ.get("GRID", "{}"))
cfg = _r(cfg, local=_r(cfg.local, **lo, grid=_r(cfg.local.grid, **gr), match=_r(cfg.local.match, **ma)))
print(lo, ma)
rec = []
orig = LocalSlam.add
def add(self, stamp, odo, cov_odo_step, *a, **k):
    n = orig(self, stamp, odo, cov_odo_step, *a, **k)
    rec.append((n.stamp_ns, n.submap, n.aTb.copy(), n.cov_aTb.copy(), n.score, n.matched, np.asarray(odo).copy()))
    return n
LocalSlam.add = add
t = time.time()
run = F._dead_reckoning(log, cfg)
closed, graph, loops = F._local_slam(run, cfg, None, None)
print("front end", time.time() - t, "s", len(rec), "nodes", len(graph.est), "anchors", "breaks", sum(k == "lost" for k in graph.kind))
gs, gp = log.ground_truth_arrays()
st = np.array([r[0] for r in rec], np.int64)
est = np.array(graph.est)
wTb = np.array([g.compose(est[r[1]], r[2]) for r in rec])
dr = g.interpolate_poses(run.dr_stamps_ns, run.dr_wTb, st)
tr = truth_at(st, gs, gp)
pickle.dump(dict(st=st, sub=np.array([r[1] for r in rec]), aTb=np.array([r[2] for r in rec]),
                 cov=np.array([r[3] for r in rec]), score=np.array([r[4] for r in rec]),
                 ok=np.array([r[5] for r in rec]), odo=np.array([r[6] for r in rec]), wTb=wTb, dr=dr, tr=tr,
                 est=est, anchor_st=np.array([sm.anchor_stamp_ns for sm in closed]),
                 kinds=list(graph.kind)), open(out, "wb"))
