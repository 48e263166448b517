"""Vision benchmark on rendered label views (holoslam.sim.label_views) and on the simulator's household log:
decode rate and false decodes per decoder and per condition (module size, tilt, in-plane rotation, motion
blur, noise, lighting, JPEG, several codes per image), corner error (px), object position error vs range
(single-view PnP, two-view triangulation), and VGA images per second on one core, with medians and a ratio
against OpenCV's
QRCodeDetector run in the same process.

    .venv/bin/python benchmarks/bench_vision.py [--n 8] [--seed 0] [--quick] [--stream on|off|only]

The default run takes about 40 s on one core, ``--quick`` about 15 s, plus the camera-stream section
(``bench_stream``: a simulated 15 fps stream of 10 minutes, ``--quick`` 2; simulated once into the temporary
folder, about 5 minutes, then about 4 minutes: the full decode of every frame and two front-end runs).
"""

from __future__ import annotations

import argparse
import math
import os
import time
from pathlib import Path

import numpy as np

from holoslam.sim.label_views import LabelInView, RenderConditions, look_at_label, render_labels_view
from holoslam.vision.camera import PinholeCamera, make_transform
from holoslam.vision.locate import pnp_label, triangulate
from holoslam.vision.qr import Decoder, Fallback, detect_qr

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
    from holoslam.sim.label_views import label_corners_o, project_points

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
    """Up to ``n`` random views, each ``(labels, [(tilt_deg, roll_deg) per label])``."""
    out = []
    for _ in range(40 * n):  # resample views that do not fit the image; give up after 40 n tries
        if len(out) >= n:
            break
        labs, meta = [], []
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
            yaw, pitch, roll = rng.uniform(-45, 45), rng.uniform(-25, 25), rng.uniform(0, 360)
            cTo = look_at_label(d, yaw, pitch, roll, off)
            ray = -cTo[:3, 3] / np.linalg.norm(cTo[:3, 3])
            tilt = math.degrees(math.acos(min(1.0, abs(float(cTo[:3, 2] @ ray)))))  # label normal vs view ray
            labs.append(LabelInView(PAYLOADS[j], side, cTo))
            meta.append((tilt, roll))
        if _fits(labs):
            out.append((labs, meta))
    return out


TILT_BINS = (0, 15, 30, 45, 60)
ROLL_BINS = (0, 45, 90, 135, 180, 225, 270, 315, 360)


def _rate(found: list[bool]) -> str:
    return f"{np.mean(found):.2f}" if found else "-"


def bench_decoders(n: int, seed: int) -> None:
    rng = np.random.default_rng(seed)
    modules = [2.0, 2.5, 3.0, 4.0, 6.0, 8.0]
    conds = list(CONDITIONS) + ["multi"]
    # one row per (decoder, label): condition, module px, tilt, roll, found
    recs: dict[str, list[tuple[str, float, float, float, bool]]] = {name: [] for name in SETUPS}
    false = {name: dict.fromkeys(conds + ["clutter"], 0) for name in SETUPS}
    err = {name: [] for name in SETUPS}
    ms = {name: [] for name in SETUPS}
    images = dict.fromkeys(conds, 0)
    for cond_name in conds:
        multi = cond_name == "multi"
        cond = RenderConditions(noise_sigma=2.0) if multi else CONDITIONS[cond_name]
        # three codes side by side fit VGA only for small modules: 2-4 px
        for m in [mm for mm in modules if not multi or mm <= 4.0]:
            for labs, meta in _views(n, rng, m, multi):
                img, truths = render_labels_view(labs, K, conditions=cond, seed=int(rng.integers(1 << 30)))
                images[cond_name] += 1
                truth = {lab.payload: t for lab, t in zip(labs, truths, strict=True)}
                for name, (decs, fb) in SETUPS.items():
                    t0 = time.perf_counter()
                    dets = detect_qr(img, decs, fb)
                    ms[name].append(1e3 * (time.perf_counter() - t0))
                    got = {}
                    for d in dets:
                        if d.payload not in truth or np.linalg.norm(d.centre - truth[d.payload].mean(0)) > 20:
                            false[name][cond_name] += 1
                        else:
                            got[d.payload] = d
                    for lab, (tilt, roll) in zip(labs, meta, strict=True):
                        ok = lab.payload in got
                        recs[name].append((cond_name, m, tilt, roll, ok))
                        if ok:
                            e = np.linalg.norm(got[lab.payload].corners - truth[lab.payload], axis=1).max()
                            err[name].append(float(e))
    n_clutter = 4 * n
    for i in range(n_clutter):  # clutter-only images: any decode is false
        img, _ = render_labels_view(
            [], K, conditions=RenderConditions(clutter=80, noise_sigma=4), seed=1000 + i
        )
        for name, (decs, fb) in SETUPS.items():
            false[name]["clutter"] += len(detect_qr(img, decs, fb))
    total = sum(images.values())
    print(
        f"\n## Decoding ({total} rendered VGA views + {n_clutter} clutter-only views, f = {F:.0f} px, "
        "label tilt "
        "0-60 deg, any in-plane rotation)"
    )
    print("decode rate by module size (px), all conditions; false decodes; corner error (max of 4 corners):")
    print(
        f"{'decoder':20s}" + "".join(f"{m:>7.1f}" for m in modules) + f"{'false':>7s}{'corner med':>12s}"
        f"{'p90 px':>8s}{'ms/img med':>12s}"
    )
    for name in SETUPS:
        rates = "".join(f"{_rate([r[4] for r in recs[name] if r[1] == m]):>7s}" for m in modules)
        e = np.array(err[name])
        print(
            f"{name:20s}{rates}{sum(false[name].values()):>7d}{np.median(e):>12.3f}"
            f"{np.percentile(e, 90):>8.3f}"
            f"{np.median(ms[name]):>12.2f}"
        )
    print(
        "\ndecode rate per condition, labels with modules >= 3 px (multi: 3 codes per image, modules 3-4 px),"
    )
    print("and false decodes per condition in brackets (clutter: views with no code):")
    print(f"{'decoder':20s}" + "".join(f"{c:>11s}" for c in conds) + f"{'clutter':>9s}")
    for name in SETUPS:
        cells = "".join(
            f"{_rate([r[4] for r in recs[name] if r[0] == c and r[1] >= 3.0]) + f' ({false[name][c]})':>11s}"
            for c in conds
        )
        print(f"{name:20s}{cells}{false[name]['clutter']:>9d}")
    print(
        "\ndecode rate by label tilt (deg, angle between the label normal and the viewing ray), "
        "modules >= 3 px:"
    )
    tb = list(zip(TILT_BINS[:-1], TILT_BINS[1:], strict=True))
    print(f"{'decoder':20s}" + "".join(f"{f'{a}-{b}':>8s}" for a, b in tb))
    for name in SETUPS:
        cells = "".join(
            f"{_rate([r[4] for r in recs[name] if a <= r[2] < b and r[1] >= 3.0]):>8s}" for a, b in tb
        )
        print(f"{name:20s}{cells}")
    print("\ndecode rate by in-plane rotation (deg), modules >= 3 px:")
    rb = list(zip(ROLL_BINS[:-1], ROLL_BINS[1:], strict=True))
    print(f"{'decoder':20s}" + "".join(f"{f'{a}-{b}':>9s}" for a, b in rb))
    for name in SETUPS:
        cells = "".join(
            f"{_rate([r[4] for r in recs[name] if a <= r[3] < b and r[1] >= 3.0]):>9s}" for a, b in rb
        )
        print(f"{name:20s}{cells}")


def bench_household_log(path: str, step: int) -> None:
    """The simulator's own rendered household views: every ``step``-th image of the bundled log, with the
    robot's tag sightings (the simulator's true projected corners) as ground truth."""
    from holoslam.io.mcap import read_log
    from holoslam.vision.label import parse_label

    try:
        log, _ = read_log(path)
    except Exception as e:  # noqa: BLE001 - the benchmark goes on without this table
        print(f"\n## Household log: not run ({path}: {e})")
        return
    tags: dict[int, dict[str, np.ndarray]] = {}
    for t in log.tags:
        tags.setdefault(t.stamp_ns, {})[t.payload] = t.corners
    ims = [im for im in log.images[::step] if im.stamp_ns in tags]
    pix = [im.decode() for im in ims]
    n_labels = sum(len(tags[im.stamp_ns]) for im in ims)
    print(
        f"\n## Household log ({path}: {len(ims)} of {len(log.images)} simulator JPEG views, "
        f"{n_labels} labels; "
        "truth = the simulator's tag corners)"
    )
    print(
        f"{'decoder':20s}{'decoded':>10s}{'false':>7s}{'corner med px':>15s}{'p90 px':>8s}{'ms/img med':>12s}"
    )
    for name, (decs, fb) in SETUPS.items():
        found, bad, errs, ms = 0, 0, [], []
        for im, px in zip(ims, pix, strict=True):
            t0 = time.perf_counter()
            dets = detect_qr(px, decs, fb)
            ms.append(1e3 * (time.perf_counter() - t0))
            truth = tags[im.stamp_ns]
            for d in dets:
                if d.payload not in truth or np.linalg.norm(d.centre - truth[d.payload].mean(0)) > 20:
                    bad += 1
                    continue
                parse_label(d.payload)
                found += 1
                errs.append(float(np.linalg.norm(d.corners - truth[d.payload], axis=1).max()))
        e = np.array(errs) if errs else np.array([math.nan])
        print(
            f"{name:20s}{f'{found}/{n_labels}':>10s}{bad:>7d}{np.median(e):>15.3f}"
            f"{np.percentile(e, 90):>8.3f}"
            f"{np.median(ms):>12.2f}"
        )


def bench_position(n: int, seed: int) -> None:
    rng = np.random.default_rng(seed + 1)
    print(
        "\n## Object position error vs range (label side 0.12 m, noise 2, blur 1 px; the PTZ zooms so modules"
        " are ~4 px:\n   f = max(600, 4 * 29 * range / 0.12); two views: 0.3 m baseline, second camera "
        "turned to"
        " the label; medians)"
    )
    print(
        f"{'range m':>8s}{'f px':>7s}{'module px':>10s}{'pnp med m':>11s}{'pnp med %':>10s}"
        f"{'2-view med m':>13s}{'2-view %':>9s}{'decoded':>9s}"
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
            f"{rng_m:>8.1f}{f:>7.0f}{mp:>10.2f}{m1:>11.4f}{100 * m1 / rng_m:>10.2f}{m2:>13.4f}"
            f"{100 * m2 / rng_m:>9.2f}{f'{ok}/{tot}':>9s}"
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
    print(f"\n## Speed, VGA, one core (cv2.setNumThreads(1); median of {reps} runs)")
    print(f"{'setup':32s}{'ms':>8s}{'images/s':>10s}{'vs cv2.QRCodeDetector':>23s}")
    print(f"{'cv2.QRCodeDetector (reference)':32s}{1e3 * t_ref:>8.2f}{1 / t_ref:>10.0f}{1.0:>23.2f}")
    for name, (decs, fb) in SETUPS.items():
        for what, im in (("1 label", img), ("no label", empty)):
            t = med(lambda im=im, decs=decs, fb=fb: detect_qr(im, decs, fb))
            print(f"{name + ', ' + what:32s}{1e3 * t:>8.2f}{1 / t:>10.0f}{t_ref / t:>23.2f}")
    t = med(lambda: detect_qr(img))
    print(f"{'default detect_qr, 1 label':32s}{1e3 * t:>8.2f}{1 / t:>10.0f}{t_ref / t:>23.2f}")


def _real_photo_folders(root: Path) -> list[tuple[str, list[tuple[Path, bytes | None]]]]:
    """(folder, [(image, expected text bytes or None when the folder holds photos without a code)])."""
    out = []
    for d in sorted(p for p in root.iterdir() if p.is_dir()):
        items = []
        for img in sorted(d.glob("*.png"), key=lambda p: (len(p.stem), p.stem)):
            txt = img.with_suffix(".txt")
            items.append((img, txt.read_bytes() if txt.is_file() else None))
        if items:
            out.append((d.name, items))
    return out


def _library_reads() -> dict:
    """The wrapped decoders called as a new user would, each with its library defaults (QR codes only)."""
    import cv2

    def zxing_plain(g):
        import zxingcpp

        return [b.text.encode("utf-8") for b in zxingcpp.read_barcodes(g, formats=zxingcpp.BarcodeFormat.QRCode)]

    def zbar_plain(g):
        from pyzbar import pyzbar

        return [r.data for r in pyzbar.decode(g, symbols=[pyzbar.ZBarSymbol.QRCODE])]

    def opencv_plain(g):
        try:
            ok, texts, _, _ = cv2.QRCodeDetector().detectAndDecodeMulti(g)
        except (cv2.error, UnicodeDecodeError):  # OpenCV raises on payloads that are not UTF-8
            return []
        return [t.encode("utf-8") for t in texts if t] if ok else []

    return {"zxing-cpp read_barcodes": zxing_plain, "pyzbar decode": zbar_plain,
            "cv2.QRCodeDetector": opencv_plain}


def bench_real_photos(root: str) -> None:
    """Real phone photos and scans (zxing's public black-box sets, copied to ``root``; see its README): per
    setup, photos whose expected text was decoded (byte for byte), photos with a decode but not the expected
    text (wrong), decodes on the photos without a code (false), and for holoslam the decodes whose corners
    were verified / refined and those whose character set the decoder guessed."""
    import cv2

    base = Path(root)
    if not base.is_dir():
        print(f"\n## Real photos: not run ({root} not found; pass --photos DIR)")
        return
    folders = _real_photo_folders(base)
    n_code = sum(1 for _, items in folders for _, t in items if t is not None)
    n_none = sum(1 for _, items in folders for _, t in items if t is None)
    reads = dict(_library_reads())
    for name, (decs, fb) in SETUPS.items():
        reads[f"holoslam {name}"] = lambda g, decs=decs, fb=fb: detect_qr(g, decs, fb)
    reads["holoslam default"] = lambda g: detect_qr(g)
    print(f"\n## Real photos ({root}: {n_code} photos with a code and known text, {n_none} without a code; "
          "text compared byte for byte)")
    cols = [f for f, _ in folders]
    print(f"{'setup':32s}" + "".join(f"{c:>18s}" for c in cols) + f"{'all':>10s}{'wrong':>7s}{'false':>7s}"
          f"{'ms/img med':>12s}")
    images = {p: cv2.imread(str(p), cv2.IMREAD_GRAYSCALE) for _, items in folders for p, _ in items}
    for name, fn in reads.items():
        cells, ok_all, wrong, false, ms = [], 0, 0, 0, []
        verified = refined = guessed = 0
        for _, items in folders:
            ok = n = 0
            for p, expected in items:
                t0 = time.perf_counter()
                got = fn(images[p])
                ms.append(1e3 * (time.perf_counter() - t0))
                texts = [g.payload.encode("utf-8") if hasattr(g, "payload") else g for g in got]
                if expected is None:
                    false += len(got)
                    continue
                n += 1
                if expected in texts:
                    ok += 1
                    d = got[texts.index(expected)]
                    verified += bool(getattr(d, "verified", False))
                    refined += bool(getattr(d, "refined", False))
                elif got:
                    wrong += 1
                guessed += sum(bool(getattr(g, "text_guessed", False)) for g in got)
            cells.append(f"{ok}/{n}" if n else f"({false} false)")
            ok_all += ok
        extra = f"   verified {verified}, refined {refined}, guessed text {guessed}" if name.startswith("holoslam") else ""
        print(f"{name:32s}" + "".join(f"{c:>18s}" for c in cells) + f"{f'{ok_all}/{n_code}':>10s}{wrong:>7d}"
              f"{false:>7d}{np.median(ms):>12.2f}{extra}")


def _stream_log(path: str | None, seed: int, duration_s: float, rate_hz: float) -> Path:
    """The stream log to measure: ``path``, or a simulated one (``holoslam.sim``, camera stream) kept in the
    temporary folder so that a second run does not simulate it again."""
    import tempfile

    from holoslam.sim import SimConfig, simulate_to_file

    if path:
        return Path(path)
    out = Path(tempfile.gettempdir()) / f"holoslam_stream_s{seed}_{duration_s:g}s_{rate_hz:g}hz.mcap"
    if not out.exists():
        t0 = time.perf_counter()
        tmp = out.with_suffix(".part")
        simulate_to_file(tmp, SimConfig(seed=seed, duration_s=duration_s, camera_rate_hz=rate_hz))
        tmp.replace(out)
        print(f"(simulated {out} in {time.perf_counter() - t0:.0f} s)")
    return out


def _stream_stages(log, settings):
    """CPU seconds of the vision stage and of the feature stage, and their results."""
    from holoslam.vision.features import object_features_from_log
    from holoslam.vision.observe import locate_from_log

    t0 = time.process_time()
    res = locate_from_log(log, stream=settings)
    t1 = time.process_time()
    feats = object_features_from_log(log, res.sightings)
    return t1 - t0, time.process_time() - t1, res, feats


def _object_rmse(log, observations):
    """Front end + solve on the log with these observations; (located ids, object RMSE m) against the world."""
    from holoslam.evaluate import object_errors, trajectory_errors, truth_at
    from holoslam.sim.world import world_from_json
    from holoslam.solve import SolveOptions, solve
    from holoslam.submaps.frontend import build_problem

    fe = build_problem(log, observations)
    sol = solve(fe.problem, SolveOptions())
    gt_t, gt_wTb = log.ground_truth_arrays()
    te = trajectory_errors(sol.wTa, truth_at(fe.anchor_stamps_ns, gt_t, gt_wTb))
    truth = {o.object_id: np.asarray(o.position[:2]) for o in world_from_json(log.world_json).objects}
    oe = object_errors(sol.landmark_ids, sol.w_landmarks, truth, te.T)
    return set(sol.landmark_ids), oe.rmse_m


def bench_stream(path: str | None, seed: int, duration_s: float, rate_hz: float, reps: int) -> None:
    """A camera stream (``holoslam.vision.stream``): the vision and feature stages with the quick look and the
    same-view skip against decoding every frame in full, on one core (CPU seconds, median of ``reps``); objects
    located by the front end + solve from each mode's observations and their RMSE against the world; frames
    without a code through the vision stage alone. Goals (issue 18): >= 300 frames of log per second for vision
    + features, no object lost, RMSE no worse; >= 500 frames without a code per second."""
    import dataclasses

    from holoslam.io.mcap import read_log
    from holoslam.vision.stream import StreamSettings

    log, _ = read_log(_stream_log(path, seed, duration_s, rate_hz))
    n = len(log.images)
    modes = {"every frame in full": StreamSettings(prefilter=False), "stream (quick look + skip)": StreamSettings()}
    rows = {}
    for name, st in modes.items():
        runs = [_stream_stages(log, st) for _ in range(1 if st.prefilter is False else reps)]
        tv, tf = float(np.median([r[0] for r in runs])), float(np.median([r[1] for r in runs]))
        rows[name] = (tv, tf, runs[-1][2], runs[-1][3], *_object_rmse(log, runs[-1][2].observations))
    print(f"\n## Camera stream: {n} frames ({n / max(duration_s, 1e-9):.0f} fps, {duration_s:g} s; simulated, "
          f"seed {seed}); CPU s on one core (median of {reps} runs; the full decode once)")
    print(f"{'mode':28s}{'vision s':>9s}{'feat s':>8s}{'frames/s':>10s}{'ratio':>7s}{'full dec':>9s}"
          f"{'no code':>9s}{'same':>6s}{'w/ codes':>9s}{'obs':>6s}{'objects':>8s}{'RMSE m':>8s}")
    ref = rows["every frame in full"]
    for name, (tv, tf, res, _feats, ids, rmse) in rows.items():
        r = res.report
        print(f"{name:28s}{tv:>9.1f}{tf:>8.1f}{n / (tv + tf):>10.0f}{(ref[0] + ref[1]) / (tv + tf):>7.2f}"
              f"{r.full_decodes:>9d}{r.skipped_no_code:>9d}{r.skipped_same_view:>6d}{r.images_decoded:>9d}"
              f"{r.observations:>6d}{len(ids):>8d}{rmse:>8.4f}")
    lost = sorted(ref[4] - rows["stream (quick look + skip)"][4])
    print(f"objects lost by the stream mode vs every frame in full: {len(lost)} {lost or ''}; features for "
          f"{len(rows['stream (quick look + skip)'][3])} vs {len(ref[3])} objects")
    full = ref[2]
    seen = {s.image_index for s in full.sightings}
    from holoslam.vision.stream import decode_gray, quick_look

    missed = [k for k in sorted(seen) if not quick_look(decode_gray(log.images[k])).candidate]
    print(f"quick look: rejected {len(missed)} of the {len(seen)} frames the full decode read a label in "
          f"({1e3 * len(missed) / max(len(seen), 1):.1f} per thousand)")
    blank = dataclasses.replace(log, images=tuple(im for k, im in enumerate(log.images) if k not in seen),
                                tags=())
    ts = [_stream_stages(blank, StreamSettings())[0] for _ in range(reps)]
    tb = float(np.median(ts))
    print(f"frames without a code (no label read by the full decode): {len(blank.images)} through the vision stage "
          f"in {tb:.2f} s CPU: {len(blank.images) / tb:.0f} frames/s (goal >= 500)")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=None, help="views per cell (default 8, --quick 2)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--quick", action="store_true", help="a smaller run (about 15 s)")
    ap.add_argument(
        "--log", default="datasets/household_small.mcap", help="simulator log with images and tags"
    )
    ap.add_argument("--photos", default=os.environ.get("HOLOSLAM_QR_PHOTOS", "../shared/qr"),
                    help="folders of real photos N.png with the expected text N.txt (none: without a code)")
    ap.add_argument("--stream", choices=["on", "off", "only"], default="on",
                    help="the camera-stream section (simulated 15 fps stream; first run simulates it, ~5 min)")
    ap.add_argument("--stream-log", default=None, help="a stream log to use instead of simulating one")
    ap.add_argument("--stream-duration", type=float, default=None, help="stream seconds (default 600, --quick 120)")
    a = ap.parse_args()
    import cv2

    cv2.setNumThreads(1)  # one core: images per second are per core
    n = a.n if a.n is not None else (2 if a.quick else 8)
    t0 = time.perf_counter()
    dur = a.stream_duration or (120.0 if a.quick else 600.0)
    if a.stream == "only":
        bench_stream(a.stream_log, 2, dur, 15.0, 3)
        print(f"\n(total {time.perf_counter() - t0:.0f} s)")
        return
    bench_decoders(n, a.seed)
    bench_household_log(a.log, 8 if a.quick else 1)
    bench_position(n, a.seed)
    bench_speed(10 if a.quick else 30)
    bench_real_photos(a.photos)
    if a.stream == "on":
        bench_stream(a.stream_log, 2, dur, 15.0, 3)
    print(f"\n(total {time.perf_counter() - t0:.0f} s)")


if __name__ == "__main__":
    main()
