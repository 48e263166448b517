"""Vision: QR labels from pixels (qr), the label payload (label), camera geometry (camera, Eq. 6-9),
object positions (locate, Eq. 16) and the object feature set (features, Eq. 13)."""
