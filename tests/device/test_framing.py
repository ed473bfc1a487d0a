"""The serial frame codec: round trips, and a fuzz of the decoder with random, truncated,
corrupted and padded streams. The decoder never raises, never returns a frame that was not
encoded exactly so, and accounts for every byte it throws away."""

import struct
import zlib

import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from mows.device.protocol.framing import (
    CRC,
    HEADER,
    MAX_PAYLOAD_BYTES,
    REJECT_CRC,
    REJECT_LENGTH,
    REJECT_PAYLOAD,
    REJECT_REASONS,
    REJECT_TRUNCATED,
    REJECT_TYPE,
    REJECT_VERSION,
    SYNC,
    VERSION,
    Frame,
    FrameDecoder,
    encode_frame,
)
from mows.device.protocol.payloads import (
    Ack,
    Coils,
    DeviceInfo,
    FieldCurrent,
    Heartbeat,
    Hello,
    Orientation,
    Samples,
    Status,
)

u8 = st.integers(0, 2**8 - 1)
u32 = st.integers(0, 2**32 - 1)
u64 = st.integers(0, 2**64 - 1)
f64 = st.floats(allow_nan=True, allow_infinity=True)
positive = st.floats(min_value=1e-300, max_value=1e300)


@st.composite
def samples(draw):
    n = draw(st.integers(1, 300))
    channels = draw(st.integers(1, 3))
    counts = draw(st.lists(st.integers(-(2**31), 2**31 - 1), min_size=n * channels, max_size=n * channels))
    flags = draw(st.lists(st.booleans(), min_size=n * channels, max_size=n * channels))
    return Samples(
        draw(u64), np.array(counts, np.int32).reshape(n, channels), np.array(flags, bool).reshape(n, channels)
    )


bodies = st.one_of(
    st.builds(DeviceInfo, positive, st.integers(1, 255), u8, positive, positive, f64, f64),
    samples(),
    st.builds(Ack, u32, u8, u64),
    st.builds(Status, u64, st.booleans(), u32, u32, u32),
    st.just(Hello()),
    st.just(Heartbeat()),
    st.builds(Coils, st.sampled_from([0, Coils.IMMEDIATE]), u64, f64, st.lists(f64, max_size=4).map(tuple)),
    st.builds(Orientation, u64, f64),
    st.builds(FieldCurrent, st.just(0), u64, f64),
    st.just(FieldCurrent(FieldCurrent.TO_ZERO_NOW, 0, 0.0)),
)
frames = st.builds(Frame, u32, u64, bodies)


def decode_in_pieces(data: bytes, cuts: list[int]) -> tuple[list[Frame], FrameDecoder]:
    """Feed ``data`` cut at ``cuts``, then end the stream; the frames and the decoder."""
    decoder = FrameDecoder()
    found = []
    edges = [0, *sorted(c % (len(data) + 1) for c in cuts), len(data)]
    for start, end in zip(edges, edges[1:]):
        found += decoder.feed(data[start:end])
    found += decoder.finish()
    return found, decoder


def assert_accounted(data: bytes, found: list[Frame], decoder: FrameDecoder) -> None:
    """Every byte fed is in a returned frame or counted as discarded; nothing is pending."""
    assert decoder.pending_bytes == 0
    assert sum(len(encode_frame(f)) for f in found) + decoder.discarded_bytes == len(data)
    assert decoder.frames == len(found)
    assert set(decoder.rejected) <= set(REJECT_REASONS)
    assert decoder.rejected_total == sum(decoder.rejected[r] for r in REJECT_REASONS)


def raw_frame(kind: int, payload: bytes, version: int = VERSION, length: int | None = None) -> bytes:
    """A frame assembled by hand, with a correct CRC for whatever header it is given."""
    header = HEADER.pack(version, kind, len(payload) if length is None else length, 1, 2)
    return SYNC + header + payload + CRC.pack(zlib.crc32(header + payload))


@given(frames)
def test_every_frame_type_round_trips(frame):
    data = encode_frame(frame)
    found, decoder = decode_in_pieces(data, [])
    assert [encode_frame(f) for f in found] == [data]
    assert decoder.rejected_total == 0 and decoder.discarded_bytes == 0


def test_a_decoded_samples_frame_has_the_encoded_values():
    counts = np.array([[100000, -100000], [0, 7], [-1, 2]], np.int32)
    saturated = np.array([[True, True], [False, False], [False, True]])
    (frame,), _ = decode_in_pieces(encode_frame(Frame(9, 123, Samples(42, counts, saturated))), [])
    assert (frame.sequence, frame.timestamp_ns, frame.body.first_sample_index) == (9, 123, 42)
    np.testing.assert_array_equal(frame.body.counts, counts)
    np.testing.assert_array_equal(frame.body.saturated, saturated)


@settings(max_examples=300)
@given(st.binary(max_size=3000), st.lists(st.integers(0, 3000), max_size=10))
def test_random_bytes_never_raise_and_are_all_accounted_for(data, cuts):
    found, decoder = decode_in_pieces(data, cuts)
    assert_accounted(data, found, decoder)


@st.composite
def damaged_streams(draw):
    """Frames, each kept intact or damaged (cut short, a bit flipped, junk inserted into it),
    with junk between frames. Returns (stream, intact frames, damaged frames whose sync word
    survived). Streams in which the junk happens to rebuild a damaged frame are left out."""
    stream, intact, damaged, sync_kept = b"", [], [], 0
    for frame in draw(st.lists(frames, min_size=1, max_size=8)):
        data = original = encode_frame(frame)
        damage = draw(st.sampled_from(["none", "truncate", "flip", "insert"]))
        if damage == "truncate":
            keep = draw(st.integers(0, len(data) - 1))
            data, sync_kept = data[:keep], sync_kept + (keep >= len(SYNC))
        elif damage == "flip":
            bit = draw(st.integers(0, 8 * len(data) - 1))
            data = bytearray(data)
            data[bit // 8] ^= 1 << (bit % 8)
            data, sync_kept = bytes(data), sync_kept + (bit >= 8 * len(SYNC))
        elif damage == "insert":
            where = draw(st.integers(len(SYNC), len(data) - 1))
            data = data[:where] + draw(st.binary(min_size=1, max_size=40)) + data[where:]
            sync_kept += 1
        if data == original:
            intact.append(frame)
        else:
            damaged.append(original)
        stream += draw(st.binary(max_size=30)) + data
    assume(not any(original in stream for original in damaged))
    return stream, intact, sync_kept


@settings(max_examples=400)
@given(damaged_streams(), st.lists(st.integers(0, 10**6), max_size=12))
def test_damaged_streams_yield_exactly_the_intact_frames(case, cuts):
    stream, intact, sync_kept = case
    found, decoder = decode_in_pieces(stream, cuts)
    assert [encode_frame(f) for f in found] == [encode_frame(f) for f in intact]
    assert_accounted(stream, found, decoder)
    # A damaged frame whose sync word survived is seen as a candidate and rejected.
    assert decoder.rejected_total >= sync_kept


@pytest.mark.parametrize(
    "data, reason",
    [
        (raw_frame(0x7F, b""), REJECT_TYPE),
        (raw_frame(Ack.TYPE, b"\x00" * 5), REJECT_PAYLOAD),
        (
            raw_frame(Samples.TYPE, struct.pack("<QHB", 0, 2, 1) + b"\x00" * 8 + b"\x01"),
            REJECT_PAYLOAD,
        ),  # stray flag bit
        (raw_frame(Coils.TYPE, struct.pack("<BQdB", 0x80, 0, 1.0, 0)), REJECT_PAYLOAD),  # unknown flag
        (
            raw_frame(DeviceInfo.TYPE, DeviceInfo.LAYOUT.pack(0.0, 2, 2, 1e-5, 1e-10, 10.0, 0.2)),
            REJECT_PAYLOAD,
        ),  # no rate
        (raw_frame(DeviceInfo.TYPE, DeviceInfo.LAYOUT.pack(2e4, 0, 2, 1e-5, 1e-10, 10.0, 0.2)), REJECT_PAYLOAD),
        (raw_frame(Hello.TYPE, b"\x00", version=2), REJECT_VERSION),
        (raw_frame(Hello.TYPE, b"", length=MAX_PAYLOAD_BYTES + 1), REJECT_LENGTH),
        (encode_frame(Frame(1, 2, Hello()))[:-1] + b"\x00", REJECT_CRC),
        (encode_frame(Frame(1, 2, Status(1, True, 0, 0, 0)))[:-3], REJECT_TRUNCATED),
    ],
)
def test_each_reason_of_rejection_is_counted(data, reason):
    good = encode_frame(Frame(5, 6, Heartbeat()))
    found, decoder = decode_in_pieces(good + data, [])
    assert [encode_frame(f) for f in found] == [good]
    assert decoder.rejected == {reason: 1}
    assert_accounted(good + data, found, decoder)


def test_a_frame_too_large_to_send_is_refused_by_the_encoder():
    counts = np.zeros((MAX_PAYLOAD_BYTES // 8 + 1, 2), np.int32)
    with pytest.raises(ValueError, match="MAX_PAYLOAD_BYTES"):
        encode_frame(Frame(0, 0, Samples(0, counts, counts.astype(bool))))
