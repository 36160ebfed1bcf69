"""InfraTec .irb: real VarioCAM images checked against the camera's screenshots, sequences, errors."""

from __future__ import annotations

import datetime as dt
import struct

import numpy as np
import pytest

from irdic.errors import ConfigError, FormatError
from irdic.io import read_ir
from irdic.io.irb import count_irb_frames, iter_irb_dataarrays, iter_irb_frames, iter_irb_headers, read_irb
from irdic.synthetic.writers import write_irb

BLOCK = 5216  # offset of the image block in both sample files (from their directories)


def _pixel_by_hand(raw: bytes, v: int, u: int, width: int = 640) -> float:
    """The documented decoding, written out with struct for one pixel (°C)."""
    palette = struct.unpack_from("<256f", raw, BLOCK + 60)
    lo, hi = struct.unpack_from("<BB", raw, BLOCK + 1728 + 2 * (v * width + u))
    return palette[hi] + (palette[hi + 1] - palette[hi]) * lo / 256.0 - 273.15


@pytest.mark.samples
@pytest.mark.parametrize("name", ["AA011400", "AB020300"])
def test_sample_size_values_and_formula(samples, name):
    path = samples / "irb" / f"{name}.irb"
    da = read_irb(path)
    assert da.dims == ("v", "u") and da.shape == (480, 640) and da.dtype == np.float32
    np.testing.assert_array_equal(da.u.values, np.arange(640))
    raw = path.read_bytes()
    for v, u in [(0, 0), (0, 639), (100, 100), (240, 320), (479, 0), (479, 639)]:
        assert da.values[v, u] == pytest.approx(_pixel_by_hand(raw, v, u), abs=2e-5)
    # inside the camera's displayed range and its -40..120 °C calibration range
    assert -40 < float(da.min()) and float(da.max()) < 120
    assert count_irb_frames(path) == 1


@pytest.mark.samples
def test_sample_metadata_matches_screenshots(samples):
    a = read_irb(samples / "irb" / "AA011400.irb")
    b = read_irb(samples / "irb" / "AB020300.irb")
    # colour bars of the screenshots: 10.0 .. 90.0 °C and 14.5 .. 21.5 °C
    assert a.attrs["shot_range"] == [10.0, 90.0]
    assert b.attrs["shot_range"] == [14.5, 21.5]
    # both scenes lie in the camera's displayed range (AB fills it, AA is a cool scene with a hot spot)
    assert 12.5 < float(b.min()) and float(b.max()) < 21.5
    assert 10.0 < float(a.min()) and float(a.max()) < 90.0
    # the file stores whole seconds; the screenshots show 17:33:46 and 00:37:09,
    # one second later than the stored time (the display clock ticks on before saving)
    assert a.attrs["rec_datetime"] == "2014-01-14T17:33:45.000"
    assert b.attrs["rec_datetime"] == "2014-02-03T00:37:08.000"
    for da, shown in ((a, dt.datetime(2014, 1, 14, 17, 33, 46)), (b, dt.datetime(2014, 2, 3, 0, 37, 9))):
        stored = dt.datetime.fromisoformat(da.attrs["rec_datetime"])
        assert abs((stored - shown).total_seconds()) <= 1.0
    assert a.attrs["device"] == "VARIOCAM" and a.attrs["emissivity"] == 1.0
    assert a.attrs["env_temp"] == 25.0 and a.attrs["calib_range"] == [-40.15, 119.85]
    assert a.attrs["distance"] == pytest.approx(0.805, abs=1e-3)
    assert b.attrs["distance"] == pytest.approx(3.212, abs=1e-3)
    assert a.attrs["wavelength"] == 9.5 and a.attrs["lens"] == "IR 1.0/30 LW"


@pytest.mark.samples
def test_orientation_matches_screenshots(samples):
    """Rows run top to bottom: no vertical flip (a public reader flips)."""
    b = read_irb(samples / "irb" / "AB020300.irb").values
    # AB020300.png: warm (yellow) ceiling beam top left, cold (dark blue) window glass bottom right,
    # and the hottest spot (red beam end) on the right edge about 200 px from the top
    beam, glass = b[60:130, 20:280].mean(), b[330:470, 400:560].mean()
    assert beam - glass > 3.0
    flipped = b[::-1]
    assert abs(flipped[60:130, 20:280].mean() - flipped[330:470, 400:560].mean()) < 0.5
    v, u = np.unravel_index(np.argmax(b), b.shape)
    assert 180 <= v <= 215 and u >= 600
    # AA011400.png: the small hot (green) spot at about (u, v) = (430, 240)
    a = read_irb(samples / "irb" / "AA011400.irb").values
    v, u = np.unravel_index(np.argmax(a), a.shape)
    assert abs(int(u) - 430) <= 8 and abs(int(v) - 245) <= 10
    assert a.max() > 35.0 and np.median(a) < 26.0


@pytest.mark.samples
def test_concatenated_variocam_hd_files(samples, tmp_path):
    """VarioCAM HD: complete IRB files end to end with a [Merge] block between them."""
    one = (samples / "irb" / "AA011400.irb").read_bytes()
    two = (samples / "irb" / "AB020300.irb").read_bytes()
    merge = b"[Merge]\r\nFiles=2\r\n" + b" " * 2000 + b"\r\n"
    path = tmp_path / "hd.irb"
    path.write_bytes(one + merge + two)
    assert count_irb_frames(path) == 2
    da = read_irb(path)
    assert da.dims == ("time", "v", "u") and da.shape == (2, 480, 640)
    np.testing.assert_array_equal(da.values[0], read_irb(samples / "irb" / "AA011400.irb").values)
    np.testing.assert_array_equal(da.values[1], read_irb(samples / "irb" / "AB020300.irb").values)
    expected = (dt.datetime(2014, 2, 3, 0, 37, 8) - dt.datetime(2014, 1, 14, 17, 33, 45)).total_seconds()
    np.testing.assert_allclose(da.time.values, [0.0, expected], atol=1e-3)
    assert da.attrs["rec_datetime"] == "2014-01-14T17:33:45.000"
    metas = [m for m, _ in iter_irb_frames(path)]
    assert [m["subfile"] for m in metas] == [0, 1]


@pytest.mark.samples
def test_dispatcher_reads_irb(samples):
    da = read_ir(samples / "irb" / "AB020300.irb")
    assert da.attrs["format"] == "irb" and da.shape == (480, 640)


# ----------------------------------------------------------------------------
# writer round trips
# ----------------------------------------------------------------------------
def test_sequence_roundtrip(tmp_path):
    rng = np.random.default_rng(1)
    frames = 20 + 15 * rng.random((4, 30, 40))
    frames[2] += 60  # a frame with another range gets its own palette
    times = np.array([0.0, 0.5, 1.0, 2.25])
    start = dt.datetime(2024, 5, 6, 7, 8, 9, 250000)
    path = write_irb(tmp_path / "s.irb", frames, times, rec_datetime=start, emissivity=0.95,
                     distance=0.8, env_temp=23.0, frame_indices=[10, 11, 12, 14])
    assert count_irb_frames(path) == 4
    da = read_irb(path)
    assert da.dims == ("time", "v", "u") and da.shape == (4, 30, 40)
    for k in range(4):
        quant = max(np.ptp(frames[k]), 1.0) / 65279  # K per code
        assert np.abs(da.values[k] - frames[k]).max() <= quant / 2 + 2e-5
    np.testing.assert_allclose(da.time.values, times, atol=1e-9)
    np.testing.assert_array_equal(da.frame_index.values, [10, 11, 12, 14])
    assert da.attrs["rec_datetime"] == "2024-05-06T07:08:09.250"
    assert da.attrs["emissivity"] == 0.95 and da.attrs["env_temp"] == 23.0 and da.attrs["n_frames"] == 4


def test_frames_as_dataarrays_keep_absolute_time(tmp_path):
    start = dt.datetime(2024, 5, 6, 7, 8, 9)
    path = write_irb(tmp_path / "s.irb", np.full((3, 2, 2), 20.0), [0.0, 0.04, 0.08], rec_datetime=start,
                     frame_indices=[5, 6, 7])
    frames = list(iter_irb_dataarrays(path))
    assert [f.dims for f in frames] == [("v", "u")] * 3
    assert [f.attrs["frame_index"] for f in frames] == [5, 6, 7]
    unix = (start - dt.datetime(1970, 1, 1)).total_seconds()
    np.testing.assert_allclose([float(f.time) for f in frames], unix + np.array([0.0, 0.04, 0.08]), atol=1e-6)
    assert frames[1].attrs["rec_datetime"] == "2024-05-06T07:08:09.040"


def test_every_code_roundtrips_within_half_a_step(tmp_path):
    # 2 x 65280 values across the range hit every palette entry and every rounding carry
    x = np.linspace(15.0, 45.0, 2 * 65280).reshape(256, 510)
    back = read_irb(write_irb(tmp_path / "dense.irb", x)).values
    step = 30.0 / 65279  # K per code
    assert np.abs(back - x).max() <= step / 2 + 2e-5


def test_single_frame_roundtrip_and_constant_frame(tmp_path):
    flat = np.full((5, 6), 21.7)
    da = read_irb(write_irb(tmp_path / "c.irb", flat))
    assert da.dims == ("v", "u")
    np.testing.assert_allclose(da.values, flat, atol=1.0 / 65279 / 2 + 2e-5)
    # extreme codes: minimum and maximum of the range survive
    x = np.linspace(-20.0, 400.0, 30).reshape(5, 6)
    back = read_irb(write_irb(tmp_path / "x.irb", x)).values
    assert np.abs(back - x).max() <= 420.0 / 65279 / 2 + 1e-4


def test_streaming_memory_does_not_grow(tmp_path):
    import tracemalloc

    frame = np.linspace(10, 30, 64 * 48).reshape(48, 64)
    short = write_irb(tmp_path / "short.irb", np.stack([frame] * 3))
    long = write_irb(tmp_path / "long.irb", np.stack([frame] * 120))

    def peak(path):
        tracemalloc.start()
        n = sum(1 for _ in iter_irb_frames(path))
        _, top = tracemalloc.get_traced_memory()
        tracemalloc.stop()
        return n, top

    (n1, p1), (n2, p2) = peak(short), peak(long)
    assert (n1, n2) == (3, 120)
    assert p2 < p1 + 64 * 1024  # 40x more frames, the same peak memory


# ----------------------------------------------------------------------------
# errors
# ----------------------------------------------------------------------------
def _small(tmp_path, n=2):
    return write_irb(tmp_path / "small.irb", 20 + np.arange(n * 12.0).reshape(n, 3, 4)).read_bytes()


def _put(tmp_path, raw, name="bad.irb"):
    p = tmp_path / name
    p.write_bytes(raw)
    return p


def test_not_an_irb_file(tmp_path):
    with pytest.raises(FormatError, match=r"no IRB signature at byte 0"):
        read_irb(_put(tmp_path, b"P5\n640 480\n255\n" + bytes(100)))


def test_truncated_files(tmp_path):
    raw = _small(tmp_path)
    with pytest.raises(FormatError, match="IRB file header at byte 0: the file ends after 40 of 64 bytes"):
        read_irb(_put(tmp_path, raw[:40], "a.irb"))
    with pytest.raises(FormatError, match="does not fit in the 100-byte file"):
        read_irb(_put(tmp_path, raw[:100], "b.irb"))
    with pytest.raises(FormatError, match=r"lies outside the \d+-byte file \(truncated"):
        read_irb(_put(tmp_path, raw[:-10], "c.irb"))


def test_compressed_images_are_refused(tmp_path):
    raw = bytearray(_small(tmp_path, 1))
    off = struct.unpack_from("<i", raw, 64 + 12)[0]
    struct.pack_into("<h", raw, off + 2, 1)
    with pytest.raises(FormatError, match="uses compression 1 which irdic cannot decode; export the sequence"):
        read_irb(_put(tmp_path, bytes(raw)))


def test_codes_outside_the_palette_scale(tmp_path):
    raw = bytearray(_small(tmp_path, 1))
    off = struct.unpack_from("<i", raw, 64 + 12)[0]
    struct.pack_into("<f", raw, off + 60 + 4 * 3, float("nan"))  # palette entry 3
    struct.pack_into("<H", raw, off + 1728, 3 * 256 + 17)  # first pixel uses it
    with pytest.raises(FormatError, match=r"palette entries 3..254, but entry 3 \(nan K .* not part of an increasing"):
        read_irb(_put(tmp_path, bytes(raw)))


def test_frames_of_different_sizes(tmp_path):
    from irdic.errors import DataError

    a = _small(tmp_path, 1)
    b = write_irb(tmp_path / "b.irb", np.full((4, 4), 20.0)).read_bytes()
    with pytest.raises(DataError, match=r"frame 1 is 4 x 4 px, frame 0 is 4 x 3 px"):
        read_irb(_put(tmp_path, a + b"[Merge]\r\n" + b))


def test_no_image_block(tmp_path):
    raw = bytearray(_small(tmp_path, 1))
    struct.pack_into("<i", raw, 64, 2)  # the only block becomes a preview
    with pytest.raises(FormatError, match="holds no image block"):
        read_irb(_put(tmp_path, bytes(raw)))


def test_writer_streams_frames_from_a_generator(tmp_path):
    frames = (np.full((3, 4), 20.0 + k) for k in range(5))
    da = read_irb(write_irb(tmp_path / "g.irb", frames, times=np.arange(5) * 0.1))
    assert da.shape == (5, 3, 4)
    np.testing.assert_allclose(da.values[:, 0, 0], 20.0 + np.arange(5), atol=1e-4)
    with pytest.raises(ConfigError, match="frames ended after 2 frames; times has 3"):
        write_irb(tmp_path / "short.irb", iter([np.zeros((2, 2))] * 2), times=[0, 1, 2])
    assert not (tmp_path / "short.irb").exists()  # no half-written file left behind
    with pytest.raises(ConfigError, match=r"frame 1 has shape \(3, 3\), frame 0 has \(2, 2\)"):
        write_irb(tmp_path / "ragged.irb", [np.zeros((2, 2)), np.zeros((3, 3))])


@pytest.mark.parametrize("kwargs,match", [
    ({"frames": np.zeros((2, 2, 2, 2))}, r"shape \(H, W\) or \(N, H, W\)"),
    ({"frames": np.full((2, 2), np.inf)}, "non-finite"),
    ({"frames": np.full((2, 2), -300.0)}, "above absolute zero"),
    ({"frames": iter([np.zeros((2, 2))])}, "times is required"),
    ({"times": [0.0, 1.0]}, "one value per frame"),
    ({"emissivity": 1.5}, "emissivity=1.5"),
    ({"rec_datetime": 5}, "datetime.datetime"),
])
def test_writer_argument_errors(tmp_path, kwargs, match):
    args = {"frames": np.zeros((2, 2))}
    args.update(kwargs)
    with pytest.raises(ConfigError, match=match):
        write_irb(tmp_path / "w.irb", **args)


def _forged_directory(tmp_path, offsets, name="forged.irb"):
    """An IRB file listing image blocks at ``offsets`` (from the first of two copies of one block)."""
    one = _small(tmp_path, 1)
    block_off, block_size = struct.unpack_from("<ii", one, 64 + 12)
    block = one[block_off:block_off + block_size]
    n = len(offsets)
    head = bytearray(one[:64])
    struct.pack_into("<iii", head, 21, 100, 64, n)
    first = 64 + 32 * n
    directory = b"".join(struct.pack("<8i", 1, 101, k + 1, first + off, block_size, 0, 1, 0)
                         for k, off in enumerate(offsets))
    return _put(tmp_path, bytes(head) + directory + block + block, name)


def test_directory_listing_one_block_many_times_is_refused(tmp_path):
    # 2,000 entries for one 1.8 kB block: read as 2,000 frames before (a 1.8 MB
    # file listing its block 40,000 times asked for 45.8 GiB)
    p = _forged_directory(tmp_path, [0] * 2000)
    assert p.stat().st_size < 70_000
    msg = r"forged\.irb: the IRB block directory lists image blocks 0 and 1 at the same byte 64064; every image"
    for call in (read_irb, count_irb_frames, read_ir, lambda q: next(iter_irb_frames(q)),
                 lambda q: next(iter_irb_dataarrays(q))):
        with pytest.raises(FormatError, match=msg):
            call(p)


def test_overlapping_image_blocks_are_refused(tmp_path):
    p = _forged_directory(tmp_path, [0, 100])
    with pytest.raises(FormatError, match=r"image blocks 0 and 1 at bytes 128 \(\+1752 bytes\) and 228, which overlap"):
        read_irb(p)
    # disjoint blocks (the second copy of the block) stay readable
    ok = _forged_directory(tmp_path, [0, 1752], "ok.irb")
    with pytest.warns(Warning):
        assert read_irb(ok).shape[0] == 2


def test_decoded_size_is_bounded_by_the_file_size(tmp_path):
    # whatever the directory says, frames come from disjoint blocks of the file
    p = _forged_directory(tmp_path, [0, 1752])
    heads = list(iter_irb_headers(p))
    assert len(heads) == 2
    assert sum(4 * h["width"] * h["height"] for h in heads) <= 2 * p.stat().st_size


def test_non_increasing_times_are_found_before_decoding(tmp_path, monkeypatch):
    import irdic.io.irb as irb

    p = write_irb(tmp_path / "d.irb", 20 + np.zeros((3, 3, 4)), [0.0, 0.5, 0.5])
    heads = list(irb.iter_irb_headers(p))
    assert [h["frame_index"] for h in heads] == [1, 2, 3]
    assert [irb.unix_time(h) - irb.unix_time(heads[0]) for h in heads] == [0.0, 0.5, 0.5]

    def no_decoding(path):
        raise AssertionError("frames decoded before the time stamps were checked")

    monkeypatch.setattr(irb, "iter_irb_frames", no_decoding)
    with pytest.warns(Warning, match=r"d\.irb: frame times do not increase \(frame 2 at 0\.500 s after frame 1"):
        with pytest.raises(AssertionError, match="frames decoded"):
            read_irb(p)
