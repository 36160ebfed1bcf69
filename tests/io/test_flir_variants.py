"""FLIR file variants met in real files of other cameras, reproduced byte for byte, and real files from a folder.

Each synthetic variant is written with :func:`irdic.synthetic.writers.write_flir`
and then changed the way a real camera's file differs (record byte order,
PNG sample order, record lengths, segment splitting, extra blocks); every
pixel is checked against the layout decoder of ``test_flir.py`` (0.01 K) and
against the scene. ``IRDIC_FLIR_FILES`` may name a folder of real FLIR files
(``.seq``, ``.csq``, ``.fff``, ``.jpg``): each is checked against the same
decoder, with Pillow decoding the PNG images.
"""

from __future__ import annotations

import os
import struct
import warnings
from pathlib import Path

import numpy as np
import pytest

from irdic.errors import FormatError, IrdicWarning
from irdic.io import detect_ir_format, read_ir
from irdic.io.flir import iter_flir_headers
from irdic.synthetic.writers import write_flir
from irdic.synthetic.writers.flir import counts_of, flir_parameters

from .test_flir import _VARIANT_PARAMS, _blocks_by_hand, _camera_by_hand, _raw2temp, _rjpeg_block, _scene, \
    _temperatures_by_hand

REAL = os.environ.get("IRDIC_FLIR_FILES")


# ----------------------------------------------------------------------------
# building blocks
# ----------------------------------------------------------------------------
def _block(tmp_path, t=None, counts=None, **kw) -> bytearray:
    """One FFF block written by ``write_flir`` (a single frame), as bytes to change."""
    path = write_flir(tmp_path / "block.fff", t, counts=counts, params=_VARIANT_PARAMS, **kw)
    return bytearray(path.read_bytes())


def _entries(block: bytes) -> list[tuple[int, int, int, int]]:
    """``(position of the entry, type, record offset, record length)`` of each directory entry."""
    hb = "<" if 100 <= struct.unpack_from("<I", block, 0x14)[0] < 200 else ">"
    at, n = struct.unpack_from(hb + "II", block, 0x18)
    out = []
    for k in range(n):
        kind, _sub, _v, _i, off, length = struct.unpack_from(hb + "HHIIII", block, at + 32 * k)
        out.append((at + 32 * k, kind, off, length))
    return out


def _record_at(block: bytes, rtype: int) -> int:
    return next(off for _pos, kind, off, _len in _entries(block) if kind == rtype)


def _set_record_length(block: bytearray, rtype: int, length: int) -> None:
    hb = "<" if 100 <= struct.unpack_from("<I", block, 0x14)[0] < 200 else ">"
    pos = next(p for p, kind, _off, _len in _entries(block) if kind == rtype)
    struct.pack_into(hb + "I", block, pos + 16, length)


def _set_raw_range(block: bytearray, median: int, rng: int) -> None:
    cam = _record_at(block, 0x20)
    cb = "<" if struct.unpack_from("<H", block, cam)[0] == 2 else ">"
    struct.pack_into(cb + "HH", block, cam + 0x338, median, rng)


def _jpeg(block: bytes, chunk: int = 65000, order=None, before: bytes = b"", fill: bool = False,
          duplicate: int | None = None, picture_segments_first: bool = False) -> bytes:
    """A radiometric JPEG carrying ``block`` in APP1 ``FLIR`` segments of ``chunk`` bytes, in ``order``."""
    import imagecodecs

    picture = imagecodecs.jpeg8_encode(np.full((8, 8), 128, np.uint8))
    parts = [block[k:k + chunk] for k in range(0, len(block), chunk)]
    segs = [b"\xff\xe1" + struct.pack(">H", 10 + len(c)) + b"FLIR\x00\x01" + bytes([k, len(parts) - 1]) + c
            for k, c in enumerate(parts)]
    if duplicate is not None:
        segs.insert(duplicate + 1, segs[duplicate])
    segs = [segs[k] for k in order] if order is not None else segs
    app1 = b"".join((b"\xff\xff" + s[1:] if fill else s) for s in segs)  # 0xFF fill byte before each marker
    if picture_segments_first:  # after the picture's own tables, just before its frame header
        sof = picture.index(b"\xff\xc0")
        return picture[:sof] + before + app1 + picture[sof:]
    return picture[:2] + before + app1 + picture[2:]


def _check_against_layout(path: Path, data: bytes, t: np.ndarray, jpeg: bool) -> None:
    """Every pixel within 0.01 K of the layout decoder and within half a count of the scene."""
    by_hand = _temperatures_by_hand(_rjpeg_block(data) if jpeg else data)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        got = read_ir(path).values.reshape(len(by_hand), *t.shape[-2:])
    for k, want in enumerate(by_hand):
        assert np.abs(got[k] - want).max() < 0.01, k
    assert np.abs(got - t.reshape(got.shape)).max() < 0.02


# ----------------------------------------------------------------------------
# variants of real cameras
# ----------------------------------------------------------------------------
@pytest.mark.parametrize("cam_length", [1148, 2108, 2428])
def test_big_endian_records_with_a_plain_png_and_no_raw_range(tmp_path, cam_length):
    """ThermaCAM EX320: big-endian header and records, PNG samples big-endian as PNG says, RawValueRange 0,
    a camera-info record of 1148 bytes (DJI Zenmuse XT: 2108, ResearchIR: 2428)."""
    t = _scene(1, 20, 28, seed=4)[0]
    block = _block(tmp_path, t, encoding="png", header_order=">", record_order=">", png_swap=False)
    _set_raw_range(block, 0, 0)
    _set_record_length(block, 0x20, cam_length)
    block[4:20] = bytes(16)  # no creator, as the camera writes
    path = tmp_path / "ex320.jpg"
    path.write_bytes(_jpeg(bytes(block)))
    _check_against_layout(path, path.read_bytes(), t, jpeg=True)
    (h,) = list(iter_flir_headers(path))
    assert (h["median"], h["range"]) == (0, 0) and h["seconds"] is not None


def test_png_samples_follow_the_record_when_the_image_cannot_tell(tmp_path):
    """A uniform image has the same roughness in both byte orders: the raw record's byte order decides."""
    counts = np.full((12, 16), 17000, np.uint16)  # 0x4268; swapped 0x6842 would be 26690 counts
    for record_order, png_swap in (("<", True), (">", False)):
        block = _block(tmp_path, counts=counts, encoding="png", header_order=">", record_order=record_order,
                       png_swap=png_swap)
        _set_raw_range(block, 0, 0)
        path = tmp_path / f"uniform{record_order == '<'}.jpg"
        path.write_bytes(_jpeg(bytes(block)))
        expected = _raw2temp(17000.0, **_camera_by_hand(bytes(block[_record_at(block, 0x20):]), record_order))
        np.testing.assert_allclose(read_ir(path).values, expected, atol=1e-4)


@pytest.mark.parametrize("png_swap", [True, False])
def test_png_order_when_the_displayed_range_misses_the_scene(tmp_path, png_swap):
    """A camera span set far from the scene puts no pixel inside it in either order: the roughness decides."""
    t = _scene(1, 20, 28, seed=5)[0]
    block = _block(tmp_path, t, encoding="png", header_order=">", record_order="<", png_swap=png_swap)
    _set_raw_range(block, 60000, 10)
    path = tmp_path / "span.jpg"
    path.write_bytes(_jpeg(bytes(block)))
    assert np.abs(read_ir(path).values - t).max() < 0.02


def test_uncompressed_subtype_1_follows_the_records_byte_order_mark(tmp_path):
    """exiftool reads raw pixels in the byte order of the record's mark, whatever the subtype says."""
    t = _scene(2, 20, 28, seed=6)
    for record_order in "<>":
        path = write_flir(tmp_path / f"a{record_order == '<'}.seq", t, subtype=1, header_order="<",
                          record_order=record_order, params=_VARIANT_PARAMS)
        _check_against_layout(path, path.read_bytes(), t, jpeg=False)


@pytest.mark.parametrize("length,has_time", [(0x38e, True), (0x38d, False), (0x310, False)])
def test_short_camera_info_records(tmp_path, length, has_time):
    """The constants end at 0x310: a shorter record has no time stamp (0x38e) or raw range (0x33e)."""
    t = _scene(1, 20, 28, seed=7)[0]
    block = _block(tmp_path, t, times=[1.7e9 + 0.5])
    _set_record_length(block, 0x20, length)
    path = tmp_path / "short.fff"
    path.write_bytes(bytes(block))
    da = read_ir(path)
    assert np.abs(da.values - t).max() < 0.02
    assert ("time" in da.coords) == has_time
    if has_time:
        assert float(da["time"]) == pytest.approx(1.7e9 + 0.5, abs=1e-6)
    _set_record_length(block, 0x20, 0x30f)
    path.write_bytes(bytes(block))
    with pytest.raises(FormatError, match=r"short.fff.*camera-info record of 783 bytes is shorter than the 784"):
        read_ir(path)


def test_frames_without_time_stamps_are_numbered_with_a_warning(tmp_path):
    path = write_flir(tmp_path / "a.seq", _scene(3, 8, 8), times=[0, 0, 0])
    with pytest.warns(IrdicWarning, match=r"a.seq: frame 0 has no time stamp: the time coordinate numbers the frames"):
        da = read_ir(path)
    np.testing.assert_array_equal(da["time"].values, [0, 1, 2])


# ----------------------------------------------------------------------------
# several FFF blocks, radiometric JPEG segments
# ----------------------------------------------------------------------------
def _other_block(magic: bytes = b"FFF\x00", rtype: int = 0x22, order: str = "<") -> bytes:
    """An FFF block of one record that is not a raw image (a file header, a palette)."""
    head = bytearray(64)
    head[:4] = magic
    head[4:11] = b"CAMCTRL"
    struct.pack_into(order + "III", head, 0x14, 100, 64, 1)
    entry = struct.pack(order + "HHIIIIIII", rtype, 1, 100, 1, 96, 64, 0, 0, 0)
    return bytes(head) + entry + bytes(range(64))


def test_blocks_without_a_raw_image_are_left_out(tmp_path):
    t = _scene(3, 20, 28, seed=8)
    raw = write_flir(tmp_path / "a.seq", t, times=[1.7e9, 1.7e9 + 0.04, 1.7e9 + 0.08]).read_bytes()
    second = list(iter_flir_headers(tmp_path / "a.seq"))[1]["offset"]
    for name, data in (("header.seq", _other_block() + raw), ("middle.seq", raw[:second] + _other_block()
                                                                + raw[second:])):
        path = tmp_path / name
        path.write_bytes(data)
        with pytest.warns(IrdicWarning, match=rf"{name}: 1 FFF block\(s\) \(the first at byte \d+\) hold no raw "
                                              r"image record \(type 1; record types 0x22\); left out"):
            da = read_ir(path)
        assert da.shape[0] == 3 and np.abs(da.values - t).max() < 0.02
        np.testing.assert_allclose(da["time"].values, [0, 0.04, 0.08], atol=1e-9)
    path = tmp_path / "none.fff"
    path.write_bytes(_other_block(order=">"))
    with pytest.raises(FormatError, match=r"none.fff.*hold no raw image record.*no frame to read"):
        read_ir(path, format="flir")


def test_bytes_between_blocks_are_skipped_to_the_next_header(tmp_path):
    """Padding or an index between frames: the chain resumes at the next complete FFF header after the gap,
    past a stray marker in the gap; the markers inside pixel data are never looked at."""
    c = counts_of(_scene(3, 20, 28, seed=10))
    c[1, 3, 4:6] = [0x4646, 0x0046]  # 'FFF\0' inside frame 1's pixels
    raw = write_flir(tmp_path / "a.seq", counts=c, times=[1.7e9, 1.7e9 + 0.04, 1.7e9 + 0.08]).read_bytes()
    second, third = (h["offset"] for h in list(iter_flir_headers(tmp_path / "a.seq"))[1:])
    gap = bytes(100) + b"FFF\x00" + bytes(60) + b"\x01" * 413  # a stray marker with no valid header behind it
    path = tmp_path / "gaps.seq"
    path.write_bytes(raw[:second] + bytes(512) + raw[second:third] + gap + raw[third:])
    with pytest.warns(IrdicWarning) as got:
        da = read_ir(path)
    messages = {str(w.message).split(": ", 1)[1] for w in got}
    why = "are not FFF data (padding, or a frame damaged beyond reading); skipped to the next FFF header at byte"
    assert messages == {f"512 bytes after frame 0 (from byte {second}) {why} {second + 512}",
                        f"577 bytes after frame 1 (from byte {third + 512}) {why} {third + 512 + 577}"}
    assert da.shape[0] == 3
    np.testing.assert_allclose(da.values, read_ir(tmp_path / "a.seq").values)
    np.testing.assert_allclose(da["time"].values, [0, 0.04, 0.08], atol=1e-9)


def test_frame_with_a_destroyed_header_is_left_out_with_a_warning(tmp_path):
    t = _scene(4, 20, 28, seed=11)
    raw = bytearray(write_flir(tmp_path / "a.seq", t, times=[1.7e9 + 0.04 * k for k in range(4)]).read_bytes())
    heads = list(iter_flir_headers(tmp_path / "a.seq"))
    raw[heads[2]["offset"]:heads[2]["offset"] + 64] = bytes(64)
    path = tmp_path / "hole.seq"
    path.write_bytes(bytes(raw))
    with pytest.warns(IrdicWarning, match=rf"hole.seq: {heads[3]['offset'] - heads[2]['offset']} bytes after frame 1 "
                                          r"\(from byte \d+\) are not FFF data \(padding, or a frame damaged"):
        da = read_ir(path)
    assert da.shape[0] == 3 and np.abs(da.values - t[[0, 1, 3]]).max() < 0.02
    np.testing.assert_allclose(da["time"].values, [0, 0.04, 0.12], atol=1e-9)  # each frame keeps its own time


def test_aff_block_without_camera_info_names_the_format(tmp_path):
    block = _block(tmp_path, _scene(1, 8, 8)[0])
    block[:4] = b"AFF\x00"
    cam_entry = next(p for p, kind, _o, _l in _entries(block) if kind == 0x20)
    block[cam_entry:cam_entry + 2] = b"\x00\x00"  # the entry unused: no camera info
    path = tmp_path / "examinir.seq"
    path.write_bytes(bytes(block))
    assert detect_ir_format(path) == "flir"
    with pytest.raises(FormatError, match=r"examinir.seq.*no camera-info record.*an AFF file"):
        read_ir(path)


@pytest.mark.parametrize("layout", [
    dict(chunk=100), dict(chunk=700, order="reversed"), dict(chunk=900, fill=True), dict(chunk=800, duplicate=1),
    dict(chunk=1000, picture_segments_first=True), dict(chunk=65000, before=b"\xff\xe2\x00\x06ICC\x00")])
def test_radiometric_jpeg_segment_layouts(tmp_path, layout):
    """Small and reversed chunks, fill bytes, a chunk saved twice, FLIR segments after the picture's tables."""
    t = _scene(1, 20, 28, seed=9)[0]
    block = bytes(_block(tmp_path, t, encoding="png", header_order=">"))
    layout = dict(layout)
    if layout.get("order") == "reversed":
        n = -(-len(block) // layout["chunk"])
        layout["order"] = list(range(n))[::-1]
    path = tmp_path / "a.jpg"
    path.write_bytes(_jpeg(block, **layout))
    assert detect_ir_format(path) == "flir"
    _check_against_layout(path, path.read_bytes(), t, jpeg=True)


def test_radiometric_jpeg_with_contradicting_or_missing_chunks(tmp_path):
    block = bytes(_block(tmp_path, _scene(1, 20, 28)[0], encoding="png", header_order=">"))
    data = bytearray(_jpeg(block, chunk=1000, duplicate=1))
    second = data.index(b"FLIR\x00\x01\x01", data.index(b"FLIR\x00\x01\x01") + 1)  # the copy of chunk 1
    data[second + 100] ^= 0xFF
    path = tmp_path / "edited.jpg"
    path.write_bytes(bytes(data))
    with pytest.raises(FormatError, match=r"edited.jpg.*FLIR APP1 segment 1 occurs twice with different"):
        read_ir(path)
    n = -(-len(block) // 1000)
    path.write_bytes(_jpeg(block, chunk=1000, order=[k for k in range(n) if k != 2]))
    with pytest.raises(FormatError, match=r"edited.jpg.*FLIR APP1 segment\(s\) \[2\] of 0\.\.\d+ are missing"):
        read_ir(path)


def test_dji_radiometric_jpeg_is_named(tmp_path):
    """DJI's later cameras write their own radiometric JPEGs (no FLIR segments): the refusal says so."""
    import imagecodecs

    picture = imagecodecs.jpeg8_encode(np.full((8, 8), 128, np.uint8))
    exif = b"Exif\x00\x00II*\x00" + b"DJI\x00" + bytes(16)
    path = tmp_path / "DJI_0001_R.JPG"
    path.write_bytes(picture[:2] + b"\xff\xe1" + struct.pack(">H", 2 + len(exif)) + exif + picture[2:])
    for fmt in ("flir", "auto"):  # forced, or told from the content
        with pytest.raises(FormatError, match=r"DJI_0001_R.JPG.*DJI radiometric JPEG in DJI's own format"):
            read_ir(path, format=fmt)


# ----------------------------------------------------------------------------
# real files from a folder
# ----------------------------------------------------------------------------
def _real_files() -> list[Path]:
    if not REAL:
        return []
    return sorted(p for p in Path(REAL).iterdir() if p.suffix.lower() in (".seq", ".csq", ".fff", ".jpg", ".jpeg"))


def _frames_by_hand(path: Path) -> list[tuple[np.ndarray, dict]]:
    """``(counts, camera parameters)`` of each frame, from the layout (Pillow for PNG, imagecodecs for JPEG-LS)."""
    import io

    import imagecodecs
    from PIL import Image

    data = path.read_bytes()
    data = _rjpeg_block(data) if data[:2] == b"\xff\xd8" else data
    data += bytes(64)  # real .csq files end a few bytes short of their last record
    out = []
    for _pos, recs, raw, cam in _blocks_by_hand(data)[:40]:
        rb = "<" if struct.unpack_from("<H", raw)[0] == 2 else ">"
        cb = "<" if struct.unpack_from("<H", cam)[0] == 2 else ">"
        w, h = struct.unpack_from(rb + "HH", raw, 2)
        sub = recs[0x01][0]
        if sub in (1, 2):
            counts = np.frombuffer(raw, rb + "u2", w * h, 32).reshape(h, w)
        elif sub == 3:
            stored = np.array(Image.open(io.BytesIO(raw[32:]))).astype(np.uint16)
            rough = [np.abs(np.diff(c.astype(float), axis=1)).mean() for c in (stored, stored.byteswap())]
            counts = stored if rough[0] < rough[1] else stored.byteswap()
        else:
            counts = imagecodecs.jpegls_decode(raw[32:])
        out.append((counts, _camera_by_hand(cam, cb)))
    return out


@pytest.mark.skipif(not _real_files(), reason="set IRDIC_FLIR_FILES to a folder of real FLIR files (.seq, .csq, "
                                              ".fff, .jpg) to check each against the layout decoder")
@pytest.mark.parametrize("path", _real_files(), ids=lambda p: p.name)
def test_real_file_against_the_layout(path):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", IrdicWarning)  # real .csq files end 4 bytes short
        da = read_ir(path)
    values = da.values.reshape(-1, *da.shape[-2:])
    frames = _frames_by_hand(path)
    assert len(frames) >= min(len(values), 40)
    rng = np.random.default_rng(0)
    for k, (counts, cam) in enumerate(frames[:len(values)]):
        h, w = counts.shape
        picks = [(0, 0), (0, w - 1), (h - 1, 0), (h - 1, w - 1), (h // 2, w // 3),
                 np.unravel_index(np.argmax(counts), counts.shape), np.unravel_index(np.argmin(counts), counts.shape),
                 *zip(rng.integers(0, h, 50), rng.integers(0, w, 50))]
        for v, u in picks:
            want = _raw2temp(float(counts[v, u]), **cam)
            got = values[k][v, u]
            assert (np.isnan(got) and not np.isfinite(want)) or abs(got - want) < 0.01, (k, v, u, got, want)


def test_counts_of_the_variant_scenes_are_in_range():
    """The scenes above stay well inside the counts (no clipping hides a wrong byte order)."""
    c = counts_of(_scene(3, 20, 28, seed=3), flir_parameters(_VARIANT_PARAMS))
    assert 1000 < c.min() and c.max() < 60000
