"""Room segmentation against ground truth: the metric of the room-segmentation benchmark of Bormann, Jordan, Li,
Hampp and Hägele ("Room Segmentation: Survey, Implementation, and Analysis", ICRA 2016), numpy only.

Ground truth: the map redrawn with a dark line across every doorway, so each room is a closed white area;
a GT room is an 8-connected area of grey > 250 with more than 100 pixels (:func:`gt_room_labels`).

A segmentation is a label image of the same size, 0 = no room; a segment is all pixels of one label value
(not a connected area) with more than 100 pixels. With overlap(s, r) the pixels segment s and GT room r share:

- ``recall`` = mean over GT rooms r of max_s overlap(s, r) / |r| (splitting a room lowers it);
- ``precision`` = mean over segments s of max_r overlap(s, r) / |s| (merging rooms lowers it);
- ``recall_pixel`` / ``precision_pixel``: the same sums pooled over pixels before dividing.

A segment's size counts all its pixels (also those on furniture or GT lines); on a furnished map a labelling
of the free pixels alone cannot reach recall 1 (the GT rooms include the furniture).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

__all__ = ["RoomScores", "gt_room_labels", "score_rooms"]

GT_WHITE_ABOVE = 250  # grey value: GT pixels above it are inside a room
MIN_PIXELS = 100  # GT rooms and segments of at most this many pixels are left out


@dataclass(frozen=True, slots=True)
class RoomScores:
    """Recall and precision (fractions) of a segmentation, per room / segment and pixel-pooled, and the
    numbers of GT rooms and segments scored."""

    recall: float
    precision: float
    recall_pixel: float
    precision_pixel: float
    gt_rooms: int
    segments: int

    def to_dict(self) -> dict:
        return asdict(self)


def gt_room_labels(gt_grey: np.ndarray) -> np.ndarray:
    """(H, W) int32 labels of the GT rooms of a ground-truth grey image (0 = no room): 8-connected areas of
    grey > 250 with more than 100 pixels, numbered 1, 2, ... in raster order of their first pixel."""
    import cv2

    g = np.asarray(gt_grey)
    if g.ndim != 2:
        raise ValueError(f"ground truth must be a 2-D grey image, got shape {g.shape}")
    n, cc = cv2.connectedComponents((g > GT_WHITE_ABOVE).astype(np.uint8), connectivity=8)
    lab = np.asarray(cc, dtype=np.int32)  # connectedComponents' labels are int32 already: no copy
    size = np.bincount(lab.ravel(), minlength=n)
    big = size > MIN_PIXELS
    big[0] = False
    first = np.full(n, lab.size, dtype=np.int64)
    np.minimum.at(first, lab.ravel(), np.arange(lab.size))
    ids = np.flatnonzero(big)
    ids = ids[np.argsort(first[ids], kind="stable")]
    out = np.zeros(n, dtype=np.int32)
    out[ids] = np.arange(1, ids.shape[0] + 1, dtype=np.int32)
    return out[lab]


def score_rooms(pred: np.ndarray, gt_labels: np.ndarray) -> RoomScores:
    """The benchmark's recall and precision (module docstring) of the label image ``pred`` against the GT
    room labels (:func:`gt_room_labels`); both (H, W), 0 = no room. NaN when there is no GT room (recall) or
    no segment (precision)."""
    p = np.asarray(pred).ravel().astype(np.int64)
    g = np.asarray(gt_labels).ravel().astype(np.int64)
    if p.shape != g.shape or np.asarray(pred).shape != np.asarray(gt_labels).shape:
        raise ValueError(
            f"prediction {np.asarray(pred).shape} and ground truth {np.asarray(gt_labels).shape} differ"
        )
    if p.size and p.min() < 0:
        raise ValueError("negative labels in the prediction; 0 is 'no room'")
    seg_ids, seg_inv, seg_size = np.unique(p, return_inverse=True, return_counts=True)
    seg_ok = (seg_ids != 0) & (seg_size > MIN_PIXELS)
    gt_ids, gt_inv, gt_size = np.unique(g, return_inverse=True, return_counts=True)
    gt_ok = (gt_ids != 0) & (gt_size > MIN_PIXELS)
    # overlaps as a sparse list of (segment, room) pairs with their pixel counts
    both = seg_ok[seg_inv] & gt_ok[gt_inv]
    pair = seg_inv[both] * gt_ids.shape[0] + gt_inv[both]
    pairs, count = np.unique(pair, return_counts=True)
    si, gi = pairs // gt_ids.shape[0], pairs % gt_ids.shape[0]
    best_seg = np.zeros(seg_ids.shape[0], dtype=np.int64)
    np.maximum.at(best_seg, si, count)
    best_gt = np.zeros(gt_ids.shape[0], dtype=np.int64)
    np.maximum.at(best_gt, gi, count)
    ns, ng = int(seg_ok.sum()), int(gt_ok.sum())
    nan = float("nan")
    return RoomScores(
        recall=float(np.mean(best_gt[gt_ok] / gt_size[gt_ok])) if ng else nan,
        precision=float(np.mean(best_seg[seg_ok] / seg_size[seg_ok])) if ns else nan,
        recall_pixel=float(best_gt[gt_ok].sum() / gt_size[gt_ok].sum()) if ng else nan,
        precision_pixel=float(best_seg[seg_ok].sum() / seg_size[seg_ok].sum()) if ns else nan,
        gt_rooms=ng,
        segments=ns,
    )
