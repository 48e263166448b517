"""Names of landmark variables (holoslam.graph.keys): a moved object's earlier place, read back without
splitting on "@" (object ids may hold one: a foreign code keyed by its payload)."""

from __future__ import annotations

import numpy as np

from holoslam.evaluate import object_errors
from holoslam.graph.keys import before_id, is_before, object_of


def test_before_names_round_trip_for_ids_with_an_at_sign():
    for oid in ("mug", "qr:bob@example.com", "a@b@c"):
        assert object_of(oid) == oid and not is_before(oid)
        assert object_of(before_id(oid)) == oid and is_before(before_id(oid))


def test_evaluation_keeps_an_object_whose_id_holds_an_at_sign_and_drops_earlier_places():
    oid = "qr:bob@example.com"
    truth = {oid: np.array([1.0, 2.0])}
    errors = object_errors([oid, before_id(oid)], np.array([[1.0, 2.1], [5.0, 5.0]]), truth, np.zeros(3))
    assert errors.n_matched == 1 and abs(errors.errors_m[oid] - 0.1) < 1e-12 and errors.unexpected == ()
