"""QR detection on rendered label views: decode, corner order and accuracy, several codes, foreign and
malformed payloads, corrupt files."""

from __future__ import annotations

import json

import numpy as np
import pytest

from holoslam.errors import ImageDecodeError, VisionError
from holoslam.sim.label_views import (
    LabelInView,
    RenderConditions,
    look_at_label,
    render_label_view,
    render_labels_view,
)
from holoslam.vision.qr import (
    Decoder,
    Fallback,
    decode_image_file,
    decoder_status,
    detect_qr,
    detection_to_json,
    orient_and_refine,
)

K = np.array([[700.0, 0, 319.5], [0, 700.0, 239.5], [0, 0, 1]])
PAYLOAD = "HL1;O07;cup;g=handle,s=60"


@pytest.mark.parametrize(
    "dist,yaw,pitch,roll",
    [(0.35, 0, 0, 0), (0.5, 35, 0, 90), (0.6, -30, 20, 200), (0.45, 10, -35, 315), (0.55, 0, 0, 45)],
)
def test_decodes_rendered_label_with_subpixel_corners(dist, yaw, pitch, roll):
    cond = RenderConditions(noise_sigma=2.0, blur_px=1.0, light_gradient=0.3)
    img, truth = render_label_view(
        PAYLOAD,
        0.06,
        look_at_label(dist, yaw, pitch, roll, (0.03, -0.02)),
        K,
        conditions=cond,
        seed=int(dist * 100) + roll,
    )
    dets = detect_qr(img)
    assert len(dets) == 1
    d = dets[0]
    assert d.payload == PAYLOAD and d.is_label and d.label.object_id == "O07" and d.error is None
    assert d.refined and d.n_modules == 25
    err = np.linalg.norm(d.corners - truth, axis=1)
    assert err.max() < 1.0, err  # the code's own order TL, TR, BR, BL, whatever the in-plane rotation


def test_refinement_beats_raw_decoder_corners():
    errs_raw, errs_ref = [], []
    for i, (yaw, roll) in enumerate([(0, 0), (30, 20), (-40, 120), (20, 250)]):
        img, truth = render_label_view(PAYLOAD, 0.06, look_at_label(0.4, yaw, roll_deg=roll), K, seed=i)
        raw = detect_qr(img, refine=False)[0]
        ref = detect_qr(img)[0]
        errs_raw.append(np.abs(raw.corners - truth).max())
        errs_ref.append(np.abs(ref.corners - truth).max())
    assert np.median(errs_ref) < 0.15 < np.median(errs_raw)


def test_several_codes_per_image_and_foreign_code():
    labs = [
        LabelInView("HL1;O01;tv;s=120", 0.12, look_at_label(1.0, 20, offset_xy=(-0.25, -0.05))),
        LabelInView("HL1;O02;cup;s=60", 0.06, look_at_label(0.5, -20, roll_deg=60, offset_xy=(0.1, 0.1))),
        LabelInView(
            "https://example.com/x", 0.08, look_at_label(0.7, 0, roll_deg=180, offset_xy=(0.2, -0.15))
        ),
    ]
    img, truths = render_labels_view(labs, K, conditions=RenderConditions(noise_sigma=2), seed=5)
    dets = {d.payload: d for d in detect_qr(img)}
    assert set(dets) == {lab.payload for lab in labs}
    for lab, t in zip(labs, truths, strict=True):
        assert np.linalg.norm(dets[lab.payload].corners - t, axis=1).max() < 1.0
    f = dets["https://example.com/x"]
    assert not f.is_label and f.foreign and f.label is None and "HL1" in f.error
    assert dets["HL1;O01;tv;s=120"].label.size_m == pytest.approx(0.12)


def test_malformed_label_payload_is_reported_not_guessed():
    img, _ = render_label_view("HL1;o7;cup", 0.06, look_at_label(0.4), K)
    (d,) = detect_qr(img)
    assert d.payload == "HL1;o7;cup" and not d.is_label and "object id" in d.error


def test_no_false_decodes_on_clutter_and_micro_qr():
    import segno

    rng = np.random.default_rng(0)
    noise = (rng.random((480, 640)) * 255).astype(np.uint8)
    blank, _ = render_labels_view([], K, conditions=RenderConditions(clutter=60, noise_sigma=5), seed=2)
    # a Micro QR code drawn big and clean must not decode: only full-size QR codes are read
    micro = np.asarray(segno.make_micro("HL1;O1;cup").matrix, np.uint8)
    big = np.kron(1 - np.pad(micro, 2), np.ones((12, 12), np.uint8)) * 255
    canvas = np.full((480, 640), 255, np.uint8)
    canvas[50 : 50 + big.shape[0], 50 : 50 + big.shape[1]] = big
    for img in (noise, blank, canvas):
        assert detect_qr(img, (Decoder.ZXING, Decoder.ZBAR, Decoder.OPENCV), Fallback.ALWAYS) == []


@pytest.mark.parametrize("decoder", [Decoder.ZXING, Decoder.ZBAR, Decoder.OPENCV, Decoder.OPENCV_ARUCO])
def test_every_decoder_gives_code_order(decoder):
    if decoder_status()[decoder.value] is not None:
        pytest.skip(decoder_status()[decoder.value])
    img, truth = render_label_view(PAYLOAD, 0.06, look_at_label(0.3, 20, roll_deg=150), K, seed=3)
    (d,) = detect_qr(img, (decoder,))
    assert d.decoder == decoder.value
    assert np.linalg.norm(d.corners - truth, axis=1).max() < 1.0


def test_orient_and_refine_recovers_order_from_any_start_and_winding():
    img, truth = render_label_view(PAYLOAD, 0.06, look_at_label(0.35, 15, roll_deg=30), K, seed=4)
    rough = truth + np.random.default_rng(1).normal(0, 0.7, (4, 2))
    for k in range(4):
        for order in ([0, 1, 2, 3], [0, 3, 2, 1]):
            c, n, refined = orient_and_refine(img, np.roll(rough[order], k, axis=0))
            assert n == 25 and refined
            assert np.linalg.norm(c - truth, axis=1).max() < 0.5
    # a quadrilateral on plain background is not a QR code
    assert orient_and_refine(np.full((480, 640), 200, np.uint8), truth) is None


def test_decode_image_file_and_json(tmp_path):
    import cv2

    img, truth = render_label_view(PAYLOAD, 0.06, look_at_label(0.4, 10), K)
    p = tmp_path / "a.png"
    cv2.imwrite(str(p), img)
    (d,) = decode_image_file(p)
    js = detection_to_json(d, str(p))
    json.dumps(js)
    assert js["image"] == str(p) and js["payload"] == PAYLOAD and not js["foreign"]
    assert js["label"] == {"id": "O07", "type": "cup", "attributes": {"g": "handle", "s": "60"}}
    assert np.allclose(js["corners"], truth, atol=1.0)


def test_corrupt_and_missing_files_raise_clear_errors(tmp_path):
    bad = tmp_path / "bad.jpg"
    bad.write_bytes(b"\xff\xd8\xff\xe0 this is not really a jpeg")
    empty = tmp_path / "empty.png"
    empty.write_bytes(b"")
    with pytest.raises(ImageDecodeError, match="bad.jpg.*not a decodable image"):
        decode_image_file(bad)
    with pytest.raises(ImageDecodeError, match="empty"):
        decode_image_file(empty)
    with pytest.raises(ImageDecodeError, match="cannot read"):
        decode_image_file(tmp_path / "missing.png")
    with pytest.raises(VisionError, match="uint8"):
        detect_qr(np.zeros((10, 10), np.float32))


def test_read_image_file_channels_and_errors(tmp_path):
    import cv2

    from holoslam.io.images import read_image_file

    bgra = np.zeros((8, 10, 4), np.uint8)
    bgra[..., 0], bgra[..., 2], bgra[..., 3] = 200, 50, 255
    p = tmp_path / "c.png"
    cv2.imwrite(str(p), bgra)
    img = read_image_file(p)
    assert (
        img.shape == (8, 10, 3) and img.dtype == np.uint8 and tuple(img[0, 0]) == (200, 0, 50)
    )  # alpha dropped
    grey = read_image_file(p, grayscale=True)
    assert (
        grey.shape == (8, 10) and abs(int(grey[0, 0]) - int(cv2.cvtColor(img, cv2.COLOR_BGR2GRAY)[0, 0])) <= 1
    )
    with pytest.raises(ImageDecodeError, match="directory"):
        read_image_file(tmp_path)
    with pytest.raises(ImageDecodeError, match="missing.png.*no such file"):
        read_image_file(tmp_path / "missing.png")


def _printed(payload, px: float, **kw) -> np.ndarray:
    """A code as printed and scanned flat: ``px`` pixels per module, quiet zone 4, slight blur."""
    import cv2
    import segno

    q = segno.make(payload, micro=False, **kw)
    m = np.asarray(q.matrix, np.uint8)
    big = (np.kron(1 - np.pad(m, 4), np.ones((10, 10), np.uint8)) * 255).astype(np.uint8)
    img = cv2.resize(big, None, fx=px / 10, fy=px / 10, interpolation=cv2.INTER_AREA)
    return cv2.GaussianBlur(img, (0, 0), 0.5)


def test_a_large_code_read_at_low_resolution_is_kept_unverified():
    # version 17 (85 modules): at 1.6 px per module the fixed pattern does not verify at the decoder's
    # corners, but the decoder read an error-corrected payload: the code is kept with its corners
    text = "x" * 600
    (d,) = detect_qr(_printed(text, 1.6, error="l"))
    assert d.payload == text and d.n_modules == 85 and not d.verified and not d.refined
    (d,) = detect_qr(_printed(text, 2.5, error="l"))  # versions above 10 verify and refine too
    assert d.payload == text and d.n_modules == 85 and d.verified and d.refined


def test_shift_jis_payload_comes_out_as_the_decoder_reads_it():
    text = "ﾃﾞｻﾞｲﾝQR 測試"
    img = _printed(text, 4, encoding="shift_jis")
    (d,) = detect_qr(img)  # zxing-cpp and zbar both read it: one code, zxing-cpp's text
    assert d.payload == text and d.decoder == "zxing" and not d.text_guessed
    assert d.raw == text.encode("shift_jis") and d.content == "text"
    if decoder_status()["zbar"] is None:
        (z,) = detect_qr(img, (Decoder.ZBAR,))
        assert z.raw == text.encode("shift_jis") and z.text_guessed  # zbar guessed the character set


def test_eci_and_binary_payloads():
    (d,) = detect_qr(_printed("Grüße", 4, encoding="iso-8859-1", eci=True))
    assert d.payload == "Grüße" and d.raw == "Grüße".encode("iso-8859-1")
    data = bytes([0, 1, 2, 250, 251, 0x80, 0x81, 0xFF])
    (b,) = detect_qr(_printed(data, 4))
    js = detection_to_json(b)
    assert b.raw == data and b.content == "binary" and js["raw_hex"] == data.hex() and js["foreign"]
    assert js["verified"] and js["refined"] and js["n_modules"] == 21
    (t,) = detect_qr(_printed(PAYLOAD, 4))
    assert detection_to_json(t)["raw_hex"] is None  # plain text: the payload is the bytes


def test_a_code_is_kept_when_its_pattern_does_not_verify(monkeypatch):
    import holoslam.vision.qr as qr

    img, truth = render_label_view(PAYLOAD, 0.06, look_at_label(0.4, 10), K)
    monkeypatch.setattr(qr, "orient_and_refine", lambda *a, **k: None)
    (d,) = qr.detect_qr(img)
    assert d.payload == PAYLOAD and d.is_label and not d.verified and not d.refined
    assert np.linalg.norm(d.corners - truth, axis=1).max() < 1.5  # the decoder's corners, in the code's order
