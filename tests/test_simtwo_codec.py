"""SimTwo's labelled strings, the RobotAtFactory datagrams and camera frames."""

import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from robotatfactory.simtwo import (FRAME_BYTES, MAX_DATAGRAM, Command, LabelledValues, ProtocolError,
                                   SensorFrame, decode_frame, decode_labels, encode_frame, encode_labels,
                                   format_real, split_lines)

# --- labelled strings -------------------------------------------------------------------------------


def test_encoding_is_simtwo_tstringlist_text():
    assert encode_labels([("Enc1", "123"), ("X", format_real(-0.725))]) == b"Enc1\r\n123\r\n\r\nX\r\n-0.725\r\n\r\n"


@pytest.mark.parametrize("v,s", [(1e-5, "1e-05"), (-0.725, "-0.725"), (123456789.0, "1.23457e+08"),
                                 (0.1 + 0.2, "0.3"), (-0.0, "0"), (3.0, "3"), (1.5707963, "1.5708")])
def test_reals_are_percent_6g(v, s):
    assert format_real(v) == s


def test_non_finite_reals_cannot_be_encoded():
    with pytest.raises(ProtocolError, match="non-finite"):
        format_real(float("nan"))


@pytest.mark.parametrize("eol", ["\r\n", "\n", "\r"])
def test_decoding_accepts_cr_lf_and_crlf(eol):
    text = eol.join(["A", "1", "", "B", "2.5", "", ""])
    assert decode_labels(text.encode()) == {"A": "1", "B": "2.5"}


def test_first_occurrence_wins_across_concatenated_datagrams():
    older = Command(0.1, 0.2, True, 7).encode()
    newer = Command(0.3, -0.4, False, 8).encode()
    got = Command.decode(older + newer)
    assert (got.v, got.w, got.magnet, got.seq) == (0.1, 0.2, True, 7)
    v = LabelledValues(older + newer)
    assert v.get_real("V") == 0.1 and v.line_of("V") == 8


def test_free_pascal_float_format_decodes():
    data = b"RAF\r\n1\r\n\r\nSeq\r\n3\r\n\r\nV\r\n1.5E-005\r\n\r\nW\r\n-2.5E+000\r\n\r\nS\r\n0\r\n\r\n"
    c = Command.decode(data)
    assert c.v == pytest.approx(1.5e-5) and c.w == -2.5 and c.magnet is False and c.seq == 3


# --- SensorFrame / Command --------------------------------------------------------------------------


def _frame(**kw):
    base = dict(seq=42, time_ms=1680, enc_delta=(17, -16), enc_total=(1234, -987), x=-0.725, y=-0.4,
                theta=1.5708, contact=False, magnet=True, ranges=np.array([0.512, -1.0, 1.2345, 0.08]))
    base.update(kw)
    return SensorFrame(**base)


def test_sensor_frame_example_from_protocol_doc():
    data = _frame().encode()
    text = data.decode()
    assert text.startswith("RAF\r\n1\r\n\r\nSeq\r\n42\r\n\r\nTms\r\n1680\r\n\r\n")
    assert "Lidar\r\n0.512;-1;1.2345;0.08\r\n\r\n" in text and text.endswith("\r\n\r\n")
    assert SensorFrame.decode(data) == _frame()


def test_full_frame_with_360_rays_fits_one_datagram():
    ranges = np.full(360, 5.99999)
    data = _frame(ranges=ranges).encode()
    assert len(data) < 8192 < MAX_DATAGRAM
    assert len(SensorFrame.decode(data).ranges) == 360


def test_no_return_rays_are_minus_one():
    f = SensorFrame.decode(_frame(ranges=np.array([np.inf, np.nan, -3.0, 1.0])).encode())
    np.testing.assert_array_equal(f.ranges, [-1, -1, -1, 1.0])


def _replace(data: bytes, label: str, value: str) -> bytes:
    return data.replace(f"{label}\r\n".encode(), f"{label}\r\n{value}\r\n\r\nIgnored\r\n".encode(), 1)


@pytest.mark.parametrize("mutate,match", [
    (lambda d: d.replace(b"Tms", b"Tmx"), r"label 'Tms' is missing"),
    (lambda d: d.replace(b"Seq\r\n42", b"Seq\r\nforty"), r"label 'Seq' \(line 5\): expected an integer, got 'forty'"),
    (lambda d: d.replace(b"X\r\n-0.725", b"X\r\nnan"), r"label 'X' \(line \d+\): 'nan' is not a finite number"),
    (lambda d: d.replace(b"Y\r\n-0.4", b"Y\r\n1e999"), r"label 'Y' .* not a finite number"),
    (lambda d: d.replace(b"Contact\r\n0", b"Contact\r\n2"), r"label 'Contact' \(line \d+\): expected 0 or 1"),
    (lambda d: d.replace(b"RAF\r\n1", b"RAF\r\n2"), r"protocol version 2; this side speaks version 1"),
    (lambda d: d.replace(b"RAF", b"FOO"), r"not a RobotAtFactory sensor frame"),
    (lambda d: d.replace(b"LidarN\r\n4", b"LidarN\r\n5"), r"4 rays, but LidarN says 5"),
    (lambda d: d.replace(b"0.512;", b"0.512;abc;"), r"ray 1 is 'abc'"),
    (lambda d: d.replace(b"0.512;", b"0.512;-2;"), r"ray 1 is '-2'"),
    (lambda d: d.replace(b"Seq\r\n42", b"Seq\r\n-5"), r"sequence number -5 is negative"),
    (lambda d: d + b"\xff\xfe", r"byte 0xff at offset \d+ is not ASCII"),
    (lambda d: d + b" " * MAX_DATAGRAM, r"exceeds the 65507-byte UDP limit"),
    (lambda d: b"", r"empty datagram"),
    (lambda d: d[: d.index(b"Lidar\r\n") + 5], r"label 'Lidar' on line \d+ has no value line"),
])
def test_malformed_frames_raise_specific_protocol_errors(mutate, match):
    with pytest.raises(ProtocolError, match=match):
        SensorFrame.decode(mutate(_frame().encode()))


def test_command_round_trip_and_errors():
    c = Command(0.3, -1.5e-05, True, 42)
    assert c.encode() == b"RAF\r\n1\r\n\r\nSeq\r\n42\r\n\r\nV\r\n0.3\r\n\r\nW\r\n-1.5e-05\r\n\r\nS\r\n1\r\n\r\n"
    assert Command.decode(c.encode()) == c
    with pytest.raises(ProtocolError, match="label 'W' is missing"):
        Command.decode(b"RAF\r\n1\r\n\r\nSeq\r\n1\r\n\r\nV\r\n0.3\r\n\r\nS\r\n1\r\n\r\n")
    with pytest.raises(ProtocolError, match="not a RobotAtFactory command"):
        Command.decode(b"V\r\n0.3\r\n\r\nW\r\n0\r\n\r\n")


def test_split_lines_does_not_break_on_other_unicode_separators():
    assert split_lines(b"a\x0bb\r\nc\x0c\r\n") == ["a\x0bb", "c\x0c"]


# --- properties ---------------------------------------------------------------------------------------

reals6 = st.floats(min_value=-1e6, max_value=1e6, allow_nan=False).map(lambda v: float("%.6g" % v))
ranges6 = st.one_of(st.just(-1.0), st.floats(min_value=0, max_value=6.0).map(lambda v: float("%.6g" % v)))
int32 = st.integers(min_value=-(2**31), max_value=2**31 - 1)


@settings(max_examples=300, deadline=None)
@given(seq=st.integers(0, 2**31 - 1), t=st.integers(0, 2**31 - 1), d=st.tuples(int32, int32),
       tot=st.tuples(int32, int32), x=reals6, y=reals6, th=reals6, c=st.booleans(), m=st.booleans(),
       r=st.lists(ranges6, max_size=360))
def test_sensor_frame_round_trips(seq, t, d, tot, x, y, th, c, m, r):
    f = SensorFrame(seq, t, d, tot, x, y, th, c, m, np.array(r, dtype=float))
    assert SensorFrame.decode(f.encode()) == f


@settings(max_examples=300, deadline=None)
@given(v=reals6, w=reals6, s=st.booleans(), seq=st.integers(-1, 2**31 - 1))
def test_command_round_trips(v, w, s, seq):
    c = Command(v, w, s, seq)
    assert Command.decode(c.encode()) == c


labels = st.text(alphabet="ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz_", min_size=1, max_size=8)
values = st.text(alphabet="0123456789.-+e ;:,", max_size=30)


@settings(max_examples=200, deadline=None)
@given(st.lists(st.tuples(labels, values), max_size=20))
def test_labelled_strings_round_trip_first_wins(items):
    # a value equal to a label is a line SimTwo's reader (the first line equal to the label) takes for the
    # label itself: the format cannot carry it, so such inputs are outside the round trip
    assume(not {v for _, v in items} & {k for k, _ in items})
    expect = {}
    for k, v in items:
        expect.setdefault(k, v)
    data = encode_labels(items)
    assert decode_labels(data) == expect
    lv = LabelledValues(data + encode_labels([(k, "later") for k in expect]))
    assert all(lv.raw(k) == v for k, v in expect.items())


@settings(max_examples=500, deadline=None)
@given(st.binary(max_size=4096))
def test_random_bytes_never_raise_anything_but_protocol_error(data):
    for decode in (SensorFrame.decode, Command.decode, decode_labels):
        try:
            decode(data)
        except ProtocolError:
            pass


@settings(max_examples=300, deadline=None)
@given(st.lists(st.sampled_from([b"RAF", b"1", b"Seq", b"-3", b"V", b"W", b"S", b"nan", b"1e5", b"", b"Lidar",
                                 b"LidarN", b"0;1;-1", b"Tms", b"X", b"\r\n", b"\r", b"\n", b"2", b";;"]), max_size=60))
def test_near_miss_datagrams_never_raise_anything_but_protocol_error(parts):
    data = b"\r\n".join(parts)
    for decode in (SensorFrame.decode, Command.decode):
        try:
            decode(data)
        except ProtocolError:
            pass


# --- camera frames ------------------------------------------------------------------------------------


def test_camera_frame_round_trip_and_row_order():
    img = np.random.default_rng(0).integers(0, 256, (480, 640, 3), dtype=np.uint8)
    raw = encode_frame(img)
    assert len(raw) == FRAME_BYTES == 1_228_800
    arr = np.frombuffer(raw, np.uint8).reshape(480, 640, 4)
    np.testing.assert_array_equal(arr[0, :, :3], img[-1])  # row 0 on the wire = bottom image row
    assert (arr[:, :, 3] == 255).all()
    back = decode_frame(raw)
    np.testing.assert_array_equal(back, img)
    assert back.flags.c_contiguous and back.dtype == np.uint8
    np.testing.assert_array_equal(decode_frame(encode_frame(img, bottom_up=False), bottom_up=False), img)
    np.testing.assert_array_equal(decode_frame(raw, bottom_up=False), img[::-1])


def test_camera_channels_are_bgra():
    img = np.zeros((480, 640, 3), np.uint8)
    img[..., 0], img[..., 1], img[..., 2] = 10, 20, 30
    px = np.frombuffer(encode_frame(img), np.uint8)[:4]
    assert px.tolist() == [10, 20, 30, 255]


@pytest.mark.parametrize("n", [0, 1, FRAME_BYTES - 1, FRAME_BYTES + 4, 640 * 480 * 3])
def test_wrong_sized_camera_frames_are_rejected(n):
    with pytest.raises(ProtocolError, match=rf"camera frame of {n} bytes; expected exactly 640\*480\*4 = 1228800"):
        decode_frame(b"\0" * n)


@settings(max_examples=50, deadline=None)
@given(st.binary(max_size=2048))
def test_random_camera_bytes_only_raise_protocol_error(data):
    with pytest.raises(ProtocolError):
        decode_frame(data)


def test_encode_frame_rejects_wrong_shapes():
    with pytest.raises(ProtocolError, match="HxWx3 uint8"):
        encode_frame(np.zeros((480, 640), np.uint8))


# ---- the optional parts labels ------------------------------------------------------------------------------

def test_parts_round_trip_and_absent_by_default():
    f = SensorFrame(3, 120, (1, 2), (10, 20), 0.1, -0.2, 0.3, False, True,
                    parts=((0.5, -0.25, 1.5708), (-0.7, 0.4, -3.1)))
    raw = f.encode()
    assert b"PartsN\r\n2\r\n" in raw
    g = SensorFrame.decode(raw)
    assert g == f and g.parts == ((0.5, -0.25, 1.5708), (-0.7, 0.4, -3.1))
    plain = SensorFrame(3, 120, (1, 2), (10, 20), 0.1, -0.2, 0.3, False, True)
    assert b"Parts" not in plain.encode() and SensorFrame.decode(plain.encode()).parts == ()


@pytest.mark.parametrize("n, values, what", [
    ("2", "0;0;0", "3 values, but PartsN 2 needs 6"),
    ("1", "0;nan;0", "not a finite number"),
    ("1", "0;x;0", "expected a real number"),
    ("-1", "", "-1 parts"),
])
def test_bad_parts_labels_are_named(n, values, what):
    raw = SensorFrame(0, 40, (0, 0), (0, 0), 0.0, 0.0, 0.0, False, False).encode()
    raw += f"PartsN\r\n{n}\r\n\r\nParts\r\n{values}\r\n\r\n".encode()
    with pytest.raises(ProtocolError, match=what):
        SensorFrame.decode(raw)


def test_a_link_lost_notice_round_trips_and_nothing_else_is_one():
    from robotatfactory.simtwo.messages import decode_link_lost, encode_link_lost

    assert decode_link_lost(encode_link_lost(1234)) == 1234
    assert decode_link_lost(encode_link_lost(0)) == 0
    assert decode_link_lost(Command(0.1, 0.0, False, 5).encode()) is None
    assert decode_link_lost(b"RAF-LINK-LOST x") is None and decode_link_lost(b"RAF-LINK-LOST") is None
