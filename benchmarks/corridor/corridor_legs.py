"""Issue 25 diagnosis: per corridor leg (truth heading within 15 deg), the distance local SLAM, the odometry and the
truth travelled; per node step (straight / turning / other) the along / across / heading errors of the increments
in the truth step frame. Usage: ``python benchmarks/corridor/corridor_legs.py OUT.pkl`` (from collect_nodes.py)."""
import pickle
import sys

import numpy as np

sys.path.insert(0, str(__import__("pathlib").Path(__file__).resolve().parents[2]))
from holoslam import geometry as g

d = pickle.load(open(sys.argv[1], "rb"))
tr, wTb, dr, st, cov, ok = d["tr"], d["wTb"], d["dr"], d["st"], d["cov"], d["ok"]
N = len(st)
def incs(P):
    return np.array([g.between(P[i], P[i + 1]) for i in range(len(P) - 1)])
dT, dS, dD = incs(tr), incs(wTb), incs(dr)
# express the estimates' increment errors in the truth step's frame: x = forward (along), y = left (across)
eS, eD = dS - dT, dD - dT
eS[:, 2] = (eS[:, 2] + np.pi) % (2 * np.pi) - np.pi
eD[:, 2] = (eD[:, 2] + np.pi) % (2 * np.pi) - np.pi
step = np.hypot(dT[:, 0], dT[:, 1])
print(f"nodes {N}, matched {ok.mean():.3f}, truth path {step.sum():.1f} m")
# legs: runs where truth heading stays within 15 deg of the run's first heading
yaw = np.unwrap(tr[:, 2])
legs, s = [], 0
for i in range(1, N):
    if abs(yaw[i] - yaw[s]) > np.radians(15):
        legs.append((s, i - 1))
        s = i
legs.append((s, N - 1))
print(f"{'leg':>3} {'nodes':>9} {'truth m':>8} {'slam m':>8} {'odo m':>8} {'slam-tr':>8} {'odo-tr':>8} {'sl acr':>7} {'od acr':>7} {'sl dyaw':>7} {'od dyaw':>7}")
tot = np.zeros(4)
for k, (a, b) in enumerate(legs):
    if b - a < 3:
        continue
    T, S, D = g.between(tr[a], tr[b]), g.between(wTb[a], wTb[b]), g.between(dr[a], dr[b])
    L = np.hypot(*T[:2])
    if L < 10:
        continue
    u = T[:2] / L  # along the leg in frame a
    def along(X, u=u):
        return X[:2] @ u

    def across(X, u=u):
        return X[0] * -u[1] + X[1] * u[0]
    tot += [L, along(S), along(D), 1]
    print(f"{k:3d} {a:4d}-{b:4d} {L:8.2f} {along(S):8.2f} {along(D):8.2f} {along(S)-L:+8.2f} {along(D)-L:+8.2f} {across(S):+7.2f} {across(D):+7.2f} {np.degrees(S[2]-T[2]):+7.2f} {np.degrees(D[2]-T[2]):+7.2f}")
print(f"straight legs >= 10 m: {int(tot[3])}, truth {tot[0]:.1f} m, slam {tot[1]:.1f} ({(tot[1]/tot[0]-1)*100:+.2f} %), odo {tot[2]:.1f} ({(tot[2]/tot[0]-1)*100:+.2f} %)")
# per step classes
turnrate = np.abs(dT[:, 2])
inleg = np.zeros(N - 1, bool)
for a, b in legs:
    if b - a >= 3 and np.hypot(*g.between(tr[a], tr[b])[:2]) >= 10:
        inleg[a:b] = True
cls = {"straight (leg>=10m)": inleg & (turnrate < np.radians(2)), "turning (>2deg/step)": turnrate >= np.radians(2),
       "other": ~inleg & (turnrate < np.radians(2))}
print(f"{'class':22} {'steps':>6} {'path m':>7} | slam along sum/mean/sd  across sd   yaw sd | odo along sum  across sd  yaw sd")
for name, m in cls.items():
    if not m.any():
        continue
    print(f"{name:22} {m.sum():6d} {step[m].sum():7.1f} | {eS[m,0].sum():+7.2f} {eS[m,0].mean()*100:+6.2f}cm {eS[m,0].std()*100:5.2f}cm {eS[m,1].std()*100:6.2f}cm {np.degrees(eS[m,2]).std():5.2f}d"
          f" | {eD[m,0].sum():+7.2f} {eD[m,1].std()*100:6.2f}cm {np.degrees(eD[m,2]).std():5.2f}d")
# matched vs not
for name, m in (("matched", ok[1:]), ("unmatched", ~ok[1:])):
    if m.any():
        print(f"{name:10} {m.sum():5d} steps: slam along err sum {eS[m,0].sum():+.2f} m, mean {eS[m,0].mean()*100:+.2f} cm/step over {step[m].sum():.1f} m")
# submap boundaries: steps where submap changes
sub = d["sub"]
chg = sub[1:] != sub[:-1]
print(f"steps across a submap change: {chg.sum()}, slam along err sum {eS[chg,0].sum():+.3f} m; within: {eS[~chg,0].sum():+.3f} m")
# covariance along vs error: node cov (relative to anchor) - look at along sigma of step's node vs actual per-step error
def R(th):
    return np.array([[np.cos(th), -np.sin(th)], [np.sin(th), np.cos(th)]])
sig_al, sig_ac = [], []
for i in range(1, N):
    C = cov[i][:2, :2]
    sig_al.append(np.sqrt(C[0, 0]))
    sig_ac.append(np.sqrt(C[1, 1]))
sig_al, sig_ac = np.array(sig_al), np.array(sig_ac)
m = cls["straight (leg>=10m)"] & ok[1:]
if m.any():
    print(f"straight matched steps: node sigma (anchor frame x,y; include drift) median {np.median(sig_al[m])*100:.2f}/{np.median(sig_ac[m])*100:.2f} cm")
# overall ATE after alignment
def ate(P, T):
    from holoslam.evaluate import trajectory_errors
    return trajectory_errors(T, P)
try:
    print("nodes ATE slam:", ate(wTb, tr))
    print("nodes ATE odo:", ate(dr, tr))
except Exception as e:
    print("ate err", e)
