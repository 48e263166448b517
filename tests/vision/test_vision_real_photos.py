"""Real phone photos and scans of QR codes (zxing's public black-box sets; not in the repository: found in
``$HOLOSLAM_QR_PHOTOS`` or ``../shared/qr`` beside the checkout, else skipped). holoslam must decode at least
as many as zxing-cpp called with its defaults, with no wrong text and no decode on the photos without a code."""

from __future__ import annotations

import os
from pathlib import Path

import pytest
from repo_paths import SHARED

ROOT = Path(os.environ.get("HOLOSLAM_QR_PHOTOS", SHARED / "qr"))

pytestmark = pytest.mark.skipif(not ROOT.is_dir(), reason=f"no real QR photos at {ROOT}")


def test_real_photos_at_least_zxing_no_wrong_text_no_false_decode():
    import cv2
    import zxingcpp

    from holoslam.vision.qr import detect_qr

    ours = theirs = wrong = false = with_code = 0
    for img_path in sorted(ROOT.glob("*/*.png")):
        gray = cv2.imread(str(img_path), cv2.IMREAD_GRAYSCALE)
        txt = img_path.with_suffix(".txt")
        got = [d.payload.encode("utf-8") for d in detect_qr(gray)]
        if not txt.is_file():
            false += len(got)
            continue
        expected = txt.read_bytes()
        with_code += 1
        ours += expected in got
        wrong += bool(got) and expected not in got
        lib = zxingcpp.read_barcodes(gray, formats=zxingcpp.BarcodeFormat.QRCode)
        theirs += expected in [b.text.encode("utf-8") for b in lib]
    assert with_code > 0
    assert ours >= theirs and wrong == 0 and false == 0, (ours, theirs, wrong, false)
