"""Vision benchmark on rendered label views (holoslam.vision.synth): decode rate and false decodes per decoder
and per condition, corner error (px), object position error vs range (single-view PnP, two-view
triangulation), and VGA images per second on one core, with medians and a ratio against OpenCV's
QRCodeDetector run in the same process.

    .venv/bin/python benchmarks/bench_vision.py [--n 8] [--seed 0]
"""

from __future__ import annotations

import argparse
import math
import time

import numpy as np

from holoslam.vision.camera import PinholeCamera, make_transform
from holoslam.vision.locate import pnp_label, triangulate
from holoslam.vision.qr import Decoder, Fallback, detect_qr
from holoslam.vision.synth import LabelInView, RenderConditions, look_at_label, render_labels_view

F = 600.0
K = np.array([[F, 0, 319.5], [0, F, 239.5], [0, 0, 1]])
CAM = PinholeCamera(K, np.zeros(5), 640, 480)
PAYLOADS = ["HL1;O07;cup;g=handle,s=60", "HL1;O12;air_conditioner;s=120", "HL1;O3;tv;m=9,s=100"]
CONDITIONS = {
    "clean": RenderConditions(),
    "blur2": RenderConditions(blur_px=2.0, blur_angle_deg=30),
    "noise8": RenderConditions(noise_sigma=8.0),
    "dark": RenderConditions(light_gain=0.35, noise_sigma=2.0),
    "gradient": RenderConditions(light_gradient=0.8, noise_sigma=2.0),
    "jpeg50": RenderConditions(jpeg_quality=50, noise_sigma=2.0),
}
SETUPS = {
    "zxing": ((Decoder.ZXING,), Fallback.NEVER),
    "zbar": ((Decoder.ZBAR,), Fallback.NEVER),
    "opencv": ((Decoder.OPENCV,), Fallback.NEVER),
    "opencv_aruco": ((Decoder.OPENCV_ARUCO,), Fallback.NEVER),
    "zxing>zbar if none": ((Decoder.ZXING, Decoder.ZBAR), Fallback.IF_EMPTY),
    "zxing+zbar always": ((Decoder.ZXING, Decoder.ZBAR), Fallback.ALWAYS),
}


def _fits(labs: list[LabelInView], w: int = 640, h: int = 480) -> bool:
    """Every label with its quiet zone fully in the image, and no two labels overlapping."""
    from holoslam.vision.synth import label_corners_o, project_points

    boxes = []
    for lab in labs:
        if lab.cTo[2, 3] <= 0.05:
            return False
        p = project_points(K, lab.cTo, label_corners_o(lab.side_m * 1.35))
        if p.min() < 2 or p[:, 0].max() > w - 3 or p[:, 1].max() > h - 3:
            return False
        boxes.append((p.min(0), p.max(0)))
    for i in range(len(boxes)):
        for j in range(i):
            if np.all(boxes[i][0] < boxes[j][1]) and np.all(boxes[j][0] < boxes[i][1]):
                return False
    return True


def _views(n: int, rng: np.random.Generator, module_px: float, multi: bool):
    out = []
    for _ in range(40 * n):  # resample views that do not fit the image; give up after 40 n tries
        if len(out) >= n:
            break
        labs = []
        k = 3 if multi else 1
        offs = [(-0.3, -0.1), (0.25, 0.0), (0.0, 0.2)] if multi else [(0.0, 0.0)]
        for j in range(k):
            side = 0.06
            n_mod = 25 if j == 0 else 29
            d = F * side / (n_mod * module_px)
            if multi:
                side = 0.06 * min(1.0, 2.5 / module_px)  # three codes must fit side by side in VGA
                d = F * side / (n_mod * module_px)
            off = (
                offs[j][0] * d + rng.uniform(-0.03, 0.03) * d,
                offs[j][1] * d + rng.uniform(-0.03, 0.03) * d,
            )
            labs.append(
                LabelInView(
                    PAYLOADS[j],
                    side,
                    look_at_label(d, rng.uniform(-45, 45), rng.uniform(-25, 25), rng.uniform(0, 360), off),
                )
            )
        if _fits(labs):
            out.append(labs)
    return out


def bench_decoders(n: int, seed: int) -> None:
    rng = np.random.default_rng(seed)
    modules = [2.0, 2.5, 3.0, 4.0, 6.0, 8.0]
    rows = {name: {"found": {}, "false": 0, "err": [], "ms": []} for name in SETUPS}
    per_cond = {name: {c: [0, 0] for c in list(CONDITIONS) + ["multi"]} for name in SETUPS}
    images = 0
    for cond_name, cond in list(CONDITIONS.items()) + [("multi", RenderConditions(noise_sigma=2.0))]:
        for m in modules:
            for labs in _views(n, rng, m, cond_name == "multi"):
                img, truths = render_labels_view(labs, K, conditions=cond, seed=int(rng.integers(1 << 30)))
                images += 1
                truth = {lab.payload: t for lab, t in zip(labs, truths)}
                for name, (decs, fb) in SETUPS.items():
                    t0 = time.perf_counter()
                    dets = detect_qr(img, decs, fb)
                    rows[name]["ms"].append(1e3 * (time.perf_counter() - t0))
                    got = {}
                    for d in dets:
                        if d.payload not in truth or np.linalg.norm(d.centre - truth[d.payload].mean(0)) > 20:
                            rows[name]["false"] += 1
                        else:
                            got[d.payload] = d
                    for p, t in truth.items():
                        key = m
                        f = rows[name]["found"].setdefault(key, [0, 0])
                        f[1] += 1
                        if m >= 3.0:
                            per_cond[name][cond_name][1] += 1
                        if p in got:
                            f[0] += 1
                            if m >= 3.0:
                                per_cond[name][cond_name][0] += 1
                            rows[name]["err"].append(float(np.linalg.norm(got[p].corners - t, axis=1).max()))
    # clutter-only images: any decode is false
    for i in range(4 * n):
        img, _ = render_labels_view(
            [], K, conditions=RenderConditions(clutter=80, noise_sigma=4), seed=1000 + i
        )
        for name, (decs, fb) in SETUPS.items():
            rows[name]["false"] += len(detect_qr(img, decs, fb))
    print(
        f"\n## Decoding ({images} rendered VGA views + {4 * n} clutter-only views, f = {F:.0f} px, random tilt "
        "<= 45 deg, any in-plane rotation)"
    )
    print("decode rate by module size (px):")
    print(
        f"{'decoder':14s}" + "".join(f"{m:>8.1f}" for m in modules) + f"{'false':>7s}{'corner err med':>16s}"
        f"{'p90 (px)':>10s}{'ms/img med':>12s}"
    )
    for name, r in rows.items():
        rates = "".join(f"{r['found'][m][0] / r['found'][m][1]:>8.2f}" for m in modules)
        e = np.array(r["err"])
        print(
            f"{name:14s}{rates}{r['false']:>7d}{np.median(e):>16.3f}{np.percentile(e, 90):>10.3f}"
            f"{np.median(r['ms']):>12.2f}"
        )
    print("\ndecode rate per condition, labels with modules >= 3 px:")
    conds = list(CONDITIONS) + ["multi"]
    print(f"{'decoder':14s}" + "".join(f"{c:>10s}" for c in conds))
    for name in SETUPS:
        print(
            f"{name:14s}"
            + "".join(f"{per_cond[name][c][0] / max(1, per_cond[name][c][1]):>10.2f}" for c in conds)
        )


def bench_position(n: int, seed: int) -> None:
    rng = np.random.default_rng(seed + 1)
    print(
        "\n## Object position error vs range (label side 0.12 m, noise 2, blur 1 px; the PTZ zooms so modules are"
        " ~4 px: f = max(600, 4 * 29 * range / 0.12); two views: 0.3 m baseline, second camera turned to the label)"
    )
    print(
        f"{'range m':>8s}{'f px':>7s}{'module px':>10s}{'pnp med m':>11s}{'pnp med %':>10s}{'2-view med m':>13s}"
        f"{'2-view %':>9s}{'decoded':>9s}"
    )
    cond = RenderConditions(noise_sigma=2.0, blur_px=1.0)
    from holoslam.vision.camera import rot_y

    for rng_m in (0.5, 1.0, 1.5, 2.0, 2.5, 3.0, 3.5):
        f = max(F, 4.0 * 29 * rng_m / 0.12)
        Kz = np.array([[f, 0, 319.5], [0, f, 239.5], [0, 0, 1]])
        cam = PinholeCamera(Kz, np.zeros(5), 640, 480)
        e1, e2, ok, tot = [], [], 0, 0
        for _ in range(n):
            tot += 1
            yaw = rng.uniform(-35, 35)
            cTo = look_at_label(
                rng_m,
                yaw,
                rng.uniform(-15, 15),
                rng.uniform(0, 360),
                (rng.uniform(-0.1, 0.1) * 0.12, rng.uniform(-0.1, 0.1) * 0.12),
            )
            img, _ = render_labels_view(
                [LabelInView(PAYLOADS[1], 0.12, cTo)], Kz, conditions=cond, seed=int(rng.integers(1 << 30))
            )
            dets = detect_qr(img)
            if not dets:
                continue
            ok += 1
            est = pnp_label(dets[0].corners, 0.12, cam)
            e1.append(np.linalg.norm(est.c_position - cTo[:3, 3]))
            # second camera 0.3 m to the right, looking at the same label
            c1Tc2 = make_transform(rot_y(math.atan2(-0.3, cTo[2, 3])), (0.3, 0.0, 0.0))
            c2To = np.linalg.inv(c1Tc2) @ cTo
            img2, _ = render_labels_view(
                [LabelInView(PAYLOADS[1], 0.12, c2To)], Kz, conditions=cond, seed=int(rng.integers(1 << 30))
            )
            d2 = detect_qr(img2)
            if d2:
                tri = triangulate(np.array([dets[0].centre, d2[0].centre]), [cam, cam], [np.eye(4), c1Tc2])
                e2.append(np.linalg.norm(tri.x_position - cTo[:3, 3]))
        mp = f * 0.12 / (rng_m * 29)
        m1 = np.median(e1) if e1 else math.nan
        m2 = np.median(e2) if e2 else math.nan
        print(
            f"{rng_m:>8.1f}{f:>7.0f}{mp:>10.2f}{m1:>11.4f}{100 * m1 / rng_m:>10.2f}{m2:>13.4f}{100 * m2 / rng_m:>9.2f}"
            f"{ok:>5d}/{tot}"
        )


def bench_speed(reps: int) -> None:
    import cv2

    labs = [LabelInView(PAYLOADS[0], 0.06, look_at_label(0.5, 20, 0, 30))]
    img, _ = render_labels_view(labs, K, conditions=RenderConditions(noise_sigma=2.0), seed=3)
    empty, _ = render_labels_view([], K, seed=4)
    ref = cv2.QRCodeDetector()

    def med(fn) -> float:
        ts = []
        for _ in range(reps):
            t0 = time.perf_counter()
            fn()
            ts.append(time.perf_counter() - t0)
        return float(np.median(ts))

    t_ref = med(lambda: ref.detectAndDecodeMulti(img))
    print("\n## Speed, VGA, one core (median of %d runs)" % reps)
    print(f"{'setup':32s}{'ms':>8s}{'images/s':>10s}{'vs cv2.QRCodeDetector':>23s}")
    print(f"{'cv2.QRCodeDetector (reference)':32s}{1e3 * t_ref:>8.2f}{1 / t_ref:>10.0f}{1.0:>23.2f}")
    for name, (decs, fb) in SETUPS.items():
        for what, im in (("1 label", img), ("no label", empty)):
            t = med(lambda: detect_qr(im, decs, fb))
            print(f"{name + ', ' + what:32s}{1e3 * t:>8.2f}{1 / t:>10.0f}{t_ref / t:>23.2f}")
    t = med(lambda: detect_qr(img))
    print(f"{'default detect_qr, 1 label':32s}{1e3 * t:>8.2f}{1 / t:>10.0f}{t_ref / t:>23.2f}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=8, help="views per cell")
    ap.add_argument("--seed", type=int, default=0)
    a = ap.parse_args()
    bench_decoders(a.n, a.seed)
    bench_position(a.n, a.seed)
    bench_speed(30)


if __name__ == "__main__":
    main()
