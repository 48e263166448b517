import pytest
from hypothesis import given
from hypothesis import strategies as st

from holoslam.errors import PayloadError
from holoslam.vision.label import MAX_PAYLOAD_CHARS, ObjectLabel, encode_label, is_label, parse_label

ids = st.from_regex(r"[A-Z0-9-]{1,16}", fullmatch=True)
kinds = st.from_regex(r"[a-z0-9_]{1,24}", fullmatch=True)
attrs = st.dictionaries(
    st.from_regex(r"[a-z]{1,8}", fullmatch=True),
    st.from_regex(r"[A-Za-z0-9._-]{0,16}", fullmatch=True),
    max_size=3,
)


@given(ids, kinds, attrs)
def test_encode_parse_round_trip(object_id, kind, attributes):
    label = ObjectLabel(object_id, kind, tuple(sorted(attributes.items())))
    try:
        text = encode_label(label)
    except PayloadError as e:  # only allowed reason: too long for a small code
        assert "characters" in str(e)
        return
    assert len(text) <= MAX_PAYLOAD_CHARS
    assert parse_label(text) == label


def test_documented_example_and_size():
    label = parse_label("HL1;O07;cup;g=handle,s=60")
    assert label.object_id == "O07" and label.kind == "cup"
    assert label.attribute("g") == "handle"
    assert label.size_m == pytest.approx(0.06)


@pytest.mark.parametrize(
    "text, needle",
    [
        ("http://example.com", "does not start with 'HL1'"),
        ("HL1;o7;cup", "object id"),
        ("HL1;O7;Cup!", "object type"),
        ("HL1;O7;cup;g", "not key=value"),
        ("HL1;O7;cup;g=a,g=b", "repeated"),
        ("HL1;O7", "fields"),
        ("HL1;O7;cup;" + "a=" + "x" * 80, "longer than"),
        ("HL1;O7;cup;a=$(rm -rf)", "not key=value"),
    ],
)
def test_malformed_payloads_say_why(text, needle):
    with pytest.raises(PayloadError, match=needle.replace("(", r"\(").replace(")", r"\)")):
        parse_label(text)
    assert not is_label(text)
