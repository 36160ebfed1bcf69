"""FLIR .seq/.csq/.fff/R-JPEG: real files against the documented formula, synthetic round trips, bad input."""

from __future__ import annotations

import math
import os
import struct
import warnings
from pathlib import Path

import numpy as np
import pytest

from irdic.errors import ConfigError, DataError, FormatError, IrdicWarning
from irdic.io import detect_ir_format, read_ir
from irdic.io.flir import iter_flir_dataarrays, iter_flir_headers
from irdic.io.flir_planck import counts_to_celsius
from irdic.synthetic.writers import write_flir
from irdic.synthetic.writers.flir import counts_of, flir_parameters

DATA = Path(__file__).resolve().parents[1] / "data" / "flir"
KELVIN = 273.15


# ----------------------------------------------------------------------------
# an independent decoder of the documented layout, one pixel at a time
# ----------------------------------------------------------------------------
def _camera_by_hand(rec: bytes, bo: str = "<") -> dict:
    f = lambda off: struct.unpack_from(bo + "f", rec, off)[0]  # noqa: E731 - the records of every sample are LE
    return {"E": f(0x20), "OD": f(0x24), "RTemp": f(0x28) - KELVIN, "ATemp": f(0x2c) - KELVIN,
            "IRWTemp": f(0x30) - KELVIN, "IRT": f(0x34), "RH": f(0x3c), "PR1": f(0x58), "PB": f(0x5c),
            "PF": f(0x60), "ATA1": f(0x70), "ATA2": f(0x74), "ATB1": f(0x78), "ATB2": f(0x7c), "ATX": f(0x80),
            "PO": struct.unpack_from(bo + "i", rec, 0x308)[0], "PR2": f(0x30c)}


def _raw2temp(raw: float, E, OD, RTemp, ATemp, IRWTemp, IRT, RH, PR1, PB, PF, PO, PR2, ATA1, ATA2, ATB1, ATB2,
              ATX) -> float:
    """Object temperature (°C) of one raw value, written term by term as Thermimage's raw2temp."""
    h2o = RH * math.exp(1.5587 + 0.06939 * ATemp - 0.00027816 * ATemp ** 2 + 0.00000068455 * ATemp ** 3)
    tau1 = ATX * math.exp(-math.sqrt(OD / 2) * (ATA1 + ATB1 * math.sqrt(h2o))) + \
        (1 - ATX) * math.exp(-math.sqrt(OD / 2) * (ATA2 + ATB2 * math.sqrt(h2o)))
    tau2 = tau1
    planck = lambda t: PR1 / (PR2 * (math.exp(PB / (t + KELVIN)) - PF)) - PO  # noqa: E731
    raw_refl1_attn = (1 - E) / E * planck(RTemp)
    raw_atm1_attn = (1 - tau1) / E / tau1 * planck(ATemp)
    raw_wind_attn = (1 - IRT) / E / tau1 / IRT * planck(IRWTemp)
    raw_atm2_attn = (1 - tau2) / E / tau1 / IRT / tau2 * planck(ATemp)
    raw_obj = raw / E / tau1 / IRT / tau2 - raw_atm1_attn - raw_atm2_attn - raw_wind_attn - raw_refl1_attn
    arg = PR1 / (PR2 * (raw_obj + PO)) + PF if raw_obj + PO > 0 else 0.0
    return PB / math.log(arg) - KELVIN if arg > 1 else math.nan  # too cold for a temperature


def _shipped_or_sample(samples_dir: Path | None, name: str) -> Path:
    for folder in (DATA, samples_dir):
        if folder is not None and (folder / name).is_file():
            return folder / name
    pytest.skip(f"{name} not found in {DATA} or the shared samples")


@pytest.fixture
def flir_samples() -> Path | None:
    """The shared samples' ``flir`` folder or None (the shipped files do not need it, so no skip here)."""
    root = Path(os.environ.get("IRDIC_SAMPLES", DATA.parents[2].parent / "shared" / "samples"))
    return root / "flir" if (root / "flir").is_dir() else None


# ----------------------------------------------------------------------------
# real files
# ----------------------------------------------------------------------------
@pytest.mark.samples
def test_documented_check_values(samples):
    """Counts 17171, 18272, 24931 under SampleSEQ's parameters: 18.3036, 24.7737, 57.0740 °C (Thermimage)."""
    (h,) = list(iter_flir_headers(samples / "flir" / "SampleSEQ.seq"))[:1]
    t = counts_to_celsius([17171, 18272, 24931], h["params"])
    np.testing.assert_allclose(t, [18.3036, 24.7737, 57.0740], atol=1e-3)


def _check_pixels(frame: np.ndarray, counts: np.ndarray, cam: dict) -> None:
    """Reader against the independent decoder at corners, centre, hottest and coldest pixels (0.01 K)."""
    h, w = counts.shape
    picks = [(0, 0), (0, w - 1), (h - 1, 0), (h - 1, w - 1), (h // 2, w // 3),
             np.unravel_index(np.argmax(counts), counts.shape), np.unravel_index(np.argmin(counts), counts.shape)]
    for v, u in picks:
        assert abs(frame[v, u] - _raw2temp(float(counts[v, u]), **cam)) < 0.01, (v, u)


@pytest.mark.samples
def test_sample_seq(samples):
    path = samples / "flir" / "SampleSEQ.seq"
    raw = path.read_bytes()
    assert detect_ir_format(path) == "flir"
    da = read_ir(path)
    assert da.dims == ("time", "v", "u") and da.shape == (2, 480, 640)
    np.testing.assert_allclose(da["time"].values, [0.0, 3.967], atol=1e-6)  # not the FrameRate of 30 Hz
    # frame 0: camera info at 320, raw at 2748; frame 1 starts at 617180 (records at 192 and 2620)
    for k, (cam_at, raw_at) in enumerate([(320, 2748), (617180 + 192, 617180 + 2620)]):
        counts = np.frombuffer(raw, "<u2", count=640 * 480, offset=raw_at + 32).reshape(480, 640)
        _check_pixels(da.values[k], counts, _camera_by_hand(raw[cam_at:cam_at + 2428]))
    assert 18.5 < float(da.min()) < 18.7 and 38.2 < float(da.max()) < 38.4
    assert da.attrs["camera"] == "FLIR SC660" and da.attrs["emissivity"] == 0.95
    assert da.attrs["reflected_temp"] == 20.0 and da.attrs["relative_humidity"] == 0.5


@pytest.mark.samples
def test_sample_csq_jpegls_and_short_last_frame(samples):
    import imagecodecs

    path = samples / "flir" / "SampleCSQ.csq"
    raw = path.read_bytes()
    with pytest.warns(IrdicWarning, match=r"SampleCSQ.csq: frame 7 ends 4 bytes short"):
        da = read_ir(path)
    assert da.shape == (8, 768, 1024)
    steps = np.diff(da["time"].values)
    assert set(np.round(steps, 3)) <= {0.033, 0.034}
    # frame 0: camera info at 256, JPEG-LS raw image at 3804 (+32) of 209392 bytes
    counts = imagecodecs.jpegls_decode(raw[3804 + 32:3804 + 209392])
    _check_pixels(da.values[0], counts, _camera_by_hand(raw[256:256 + 2476]))
    assert 15.6 < float(da.min()) < 15.8 and 35.4 < float(da.max()) < 35.6
    assert np.isfinite(da.values).all()


def test_shipped_fff_duo_pro_r(flir_samples):
    path = _shipped_or_sample(flir_samples, "frame_000000.fff")
    raw = path.read_bytes()
    da = read_ir(path)
    assert da.dims == ("v", "u") and da.shape == (512, 640)
    # big-endian FFF header, little-endian records: raw image at 512, camera info at 655904
    counts = np.frombuffer(raw, "<u2", count=640 * 512, offset=512 + 32).reshape(512, 640)
    cam = _camera_by_hand(raw[655904:655904 + 2476])
    assert cam["PR1"] > 3e5 and cam["PR2"] == 1.0 and cam["PO"] == -228  # unlike the hand-held cameras
    _check_pixels(da.values, counts, cam)
    assert 9.5 < float(da.min()) < 9.7 and 12.5 < float(da.max()) < 12.7
    assert da.attrs["emissivity"] == pytest.approx(0.94, abs=1e-3) and da.attrs["distance"] == 50.0
    assert da.attrs["relative_humidity"] == pytest.approx(0.3)


def _rjpeg_block(raw: bytes) -> bytes:
    """The FFF block of a radiometric JPEG, from its APP1 'FLIR' segments (written out independently)."""
    pos, parts = 2, {}
    while raw[pos] == 0xFF and raw[pos + 1] != 0xDA:
        if raw[pos + 1] == 0xFF:  # a fill byte
            pos += 1
            continue
        n = struct.unpack_from(">H", raw, pos + 2)[0]
        seg = raw[pos + 4:pos + 2 + n]
        if raw[pos + 1] == 0xE1 and seg.startswith(b"FLIR\x00"):
            parts[seg[6]] = seg[8:]
        pos += 2 + n
    return b"".join(parts[k] for k in sorted(parts))


def test_shipped_rjpeg_t640(flir_samples):
    import imagecodecs

    path = _shipped_or_sample(flir_samples, "FLIR_T640.jpg")
    raw = path.read_bytes()
    assert detect_ir_format(path) == "flir"
    da = read_ir(path)
    assert da.dims == ("v", "u") and da.shape == (480, 640)
    block = _rjpeg_block(raw)
    (n,) = struct.unpack_from(">I", block, 0x1c)  # big-endian header
    entries = [struct.unpack_from(">HHIIII", block, 64 + 32 * k) for k in range(n)]
    (_, sub, _, _, raw_at, raw_len), = [e for e in entries if e[0] == 1]
    (_, _, _, _, cam_at, cam_len), = [e for e in entries if e[0] == 0x20]
    assert sub == 3
    counts = imagecodecs.png_decode(block[raw_at + 32:raw_at + raw_len]).byteswap()  # LE samples in a PNG
    _check_pixels(da.values, counts, _camera_by_hand(block[cam_at:cam_at + cam_len]))
    assert 25.4 < float(da.min()) < 25.6 and 97.8 < float(da.max()) < 98.0


def test_rjpeg_orientation_matches_its_colour_picture(flir_samples):
    """The camera's colour-mapped picture (a centred digital zoom) fits the image upright, not flipped."""
    import imagecodecs
    from skimage.transform import resize

    path = _shipped_or_sample(flir_samples, "FLIR_T640.jpg")
    t = read_ir(path).values
    rgb = resize(imagecodecs.jpeg8_decode(path.read_bytes()).astype(float), (96, 128, 3), anti_aliasing=True)
    design = np.c_[rgb.reshape(-1, 3), np.ones(96 * 128)]

    def fit(img):  # R^2 of temperature against the colour channels over a few zooms
        best = 0.0
        for s in (1.5, 1.625, 1.75):
            h, w = int(480 / s), int(640 / s)
            c = resize(img[(480 - h) // 2:(480 - h) // 2 + h, (640 - w) // 2:(640 - w) // 2 + w], (96, 128),
                       anti_aliasing=True).ravel()
            res = np.linalg.lstsq(design, c, rcond=None)[1][0]
            best = max(best, 1 - res / ((c - c.mean()) ** 2).sum())
        return best

    upright, flipped_v, flipped_u = fit(t), fit(t[::-1]), fit(t[:, ::-1])
    assert upright > 0.5 and upright > 2 * max(flipped_v, flipped_u)


# ----------------------------------------------------------------------------
# synthetic files
# ----------------------------------------------------------------------------
def _scene(n=3, h=24, w=32, seed=0):
    rng = np.random.default_rng(seed)
    v, u = np.mgrid[:h, :w]
    return np.stack([20 + 0.4 * u + 0.2 * v + k + rng.normal(0, 0.3, (h, w)) for k in range(n)])


@pytest.mark.parametrize("encoding", ["raw", "png", "jpegls"])
@pytest.mark.parametrize("header_order,record_order", [("<", "<"), (">", "<"), (">", ">"), ("<", ">")])
def test_roundtrip_seq(tmp_path, encoding, header_order, record_order):
    t = _scene()
    times = [1.7e9 + 0.25, 1.7e9 + 0.283, 1.7e9 + 0.317]
    path = write_flir(tmp_path / "a.seq", t, times=times, encoding=encoding, header_order=header_order,
                      record_order=record_order)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        da = read_ir(path)
    expected = counts_to_celsius(counts_of(t), flir_parameters())
    np.testing.assert_allclose(da.values, expected, atol=1e-4)  # float32 of the exact per-count value
    assert np.abs(da.values - t).max() < 0.01  # half a count is about 0.003 K here
    np.testing.assert_allclose(da["time"].values, [0.0, 0.033, 0.067], atol=1e-9)
    assert list(da["frame_index"].values) == [0, 1, 2]
    stamps = [float(f["time"]) for f in iter_flir_dataarrays(path)]
    np.testing.assert_allclose(stamps, times, atol=1e-6)


@pytest.mark.parametrize("encoding", ["raw", "png"])
@pytest.mark.parametrize("header_order", ["<", ">"])
def test_roundtrip_rjpeg(tmp_path, encoding, header_order):
    t = _scene(1, 30, 20)[0]  # portrait
    path = write_flir(tmp_path / "a.jpg", t, jpeg=True, encoding=encoding, header_order=header_order)
    assert detect_ir_format(path) == "flir"
    da = read_ir(path)
    assert da.dims == ("v", "u") and da.shape == (30, 20)
    assert np.abs(da.values - t).max() < 0.01


def test_png_stored_big_endian_is_read_as_well(tmp_path):
    t = _scene(1)[0]
    da = read_ir(write_flir(tmp_path / "a.jpg", t, jpeg=True, encoding="png", png_swap=False))
    assert np.abs(da.values - t).max() < 0.01


def test_marker_inside_pixel_data(tmp_path):
    c = counts_of(_scene())
    c[1, 5, 10:12] = [0x4646, 0x0046]  # little-endian bytes 'FFF\0' inside frame 1's pixels
    c[2, 0, 0:2] = [0x4646, 0x0046]
    path = write_flir(tmp_path / "a.seq", counts=c)
    assert path.read_bytes().count(b"FFF\x00") == 5
    da = read_ir(path)
    assert da.shape[0] == 3
    np.testing.assert_allclose(da.values, counts_to_celsius(c, flir_parameters()), atol=1e-4)


def test_records_after_the_raw_image_are_part_of_the_frame(tmp_path):
    """The next frame starts after the block's last record, whatever the directory order."""
    t = _scene()
    for encoding in ("raw", "jpegls"):
        path = write_flir(tmp_path / f"a_{encoding}.seq", t, extra_records=2, encoding=encoding)
        offsets = [h["offset"] for h in iter_flir_headers(path)]
        assert len(offsets) == 3
        if encoding == "raw":  # frames 1 and 2 are alike: the file ends one frame length after frame 2
            assert path.stat().st_size == offsets[2] + offsets[2] - offsets[1]
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            assert np.abs(read_ir(path).values - t).max() < 0.01


def test_truncated_last_frame(tmp_path):
    c = counts_of(_scene())
    raw = write_flir(tmp_path / "a.seq", counts=c).read_bytes()
    path = tmp_path / "cut.seq"
    path.write_bytes(raw[:-100])
    with pytest.warns(IrdicWarning, match=r"cut.seq: frame 2 ends 100 bytes short.*50 missing pixels are NaN"):
        da = read_ir(path)
    assert da.shape[0] == 3
    last = da.values[2].ravel()
    assert np.isnan(last[-50:]).all() and np.isfinite(last[:-50]).all()
    np.testing.assert_allclose(last[:-50], counts_to_celsius(c[2].ravel()[:-50], flir_parameters()), atol=1e-4)
    # cut inside the last frame's camera info (it starts 128 bytes into the frame), or inside its header
    third = list(iter_flir_headers(tmp_path / "a.seq"))[2]["offset"]
    for cut in (third + 400, third + 30):
        path.write_bytes(raw[:cut])
        with pytest.warns(IrdicWarning, match=r"cut.seq: frame 2 is cut off.*left out"):
            da = read_ir(path)
        assert da.shape[0] == 2
        np.testing.assert_allclose(da.values, counts_to_celsius(c[:2], flir_parameters()), atol=1e-4)


def test_compressed_last_frame_missing_padding(tmp_path):
    path = write_flir(tmp_path / "a.csq", _scene(), encoding="jpegls")
    raw = bytearray(path.read_bytes())
    last = list(iter_flir_headers(path))[-1]["offset"]
    length_at = last + 64 + 16  # raw image entry (first in the directory): u32 length
    struct.pack_into("<I", raw, length_at, struct.unpack_from("<I", raw, length_at)[0] + 4)
    path.write_bytes(bytes(raw))
    with pytest.warns(IrdicWarning, match=r"a.csq: frame 2 ends 4 bytes short.*image itself is complete"):
        da = read_ir(path)
    assert da.shape[0] == 3 and np.isfinite(da.values).all()


def test_unknown_compression(tmp_path):
    path = write_flir(tmp_path / "a.seq", _scene(), subtype=7)
    with pytest.raises(FormatError, match=r"a.seq.*frame 0: raw image encoding \(subtype\) 7"):
        read_ir(path)


def test_frames_changing_size(tmp_path):
    t = _scene()
    path = write_flir(tmp_path / "a.seq", [t[0], t[1][:, :30], t[2]])
    with pytest.raises(DataError, match=r"a.seq: frame 1 is 30 x 24 px, frame 0 is 32 x 24 px"):
        read_ir(path)


def test_camera_parameters_changing_within_the_record(tmp_path):
    t = _scene()
    params = [None, {"emissivity": 0.9}, {"emissivity": 0.9}]
    path = write_flir(tmp_path / "a.seq", t, params=params)
    with pytest.warns(IrdicWarning, match=r"a.seq: frame 1 changes the camera parameters \(emissivity\)"):
        da = read_ir(path)
    assert np.abs(da.values - t).max() < 0.01  # each frame with its own emissivity


def test_times_not_increasing(tmp_path):
    path = write_flir(tmp_path / "a.seq", _scene(), times=[1.7e9, 1.7e9 + 1, 1.7e9 + 0.5])
    with pytest.warns(IrdicWarning, match=r"a.seq: frame times do not increase \(frame 2"):
        read_ir(path)


def test_broken_chain_and_trailing_bytes(tmp_path):
    raw = write_flir(tmp_path / "a.seq", _scene()).read_bytes()
    second = list(iter_flir_headers(tmp_path / "a.seq"))[1]["offset"]
    bad = bytearray(raw)
    struct.pack_into("<I", bad, second + 0x14, 7)  # frame 1's version
    path = tmp_path / "b.seq"
    path.write_bytes(bytes(bad))
    with pytest.raises(FormatError, match=r"b.seq.*frame 1 \(byte \d+\): FFF version 7"):
        read_ir(path)
    path.write_bytes(raw + b"\x01" * 200)
    with pytest.warns(IrdicWarning, match=r"b.seq: 200 bytes after frame 2 are not an FFF frame"):
        assert read_ir(path).shape[0] == 3


def test_plain_jpeg_and_other_files_are_refused(tmp_path):
    import imagecodecs

    path = tmp_path / "photo.jpg"
    path.write_bytes(imagecodecs.jpeg8_encode(np.zeros((8, 8), np.uint8)))
    with pytest.raises(FormatError, match="JPEG without FLIR radiometric data"):
        read_ir(path)
    with pytest.raises(FormatError, match="JPEG without FLIR radiometric data"):
        read_ir(path, format="flir")
    (tmp_path / "x.seq").write_bytes(b"\x00" * 100)
    with pytest.raises(FormatError, match="no FFF header"):
        read_ir(tmp_path / "x.seq", format="flir")


def test_overrides(tmp_path):
    t = _scene(2)
    path = write_flir(tmp_path / "a.seq", t)
    da = read_ir(path, emissivity=0.8, reflected_temperature=35.0)
    p = dict(flir_parameters(), emissivity=0.8, reflected_k=35.0 + KELVIN)
    np.testing.assert_allclose(da.values, counts_to_celsius(counts_of(t), p), atol=1e-4)
    assert da.attrs["emissivity"] == 0.8 and da.attrs["reflected_temp"] == 35.0
    # more reflection from surroundings hotter than the scene: the surface reads colder than with the file's values
    assert (da.values < t).all() and (da.values < t - 3)[t < 22].all()
    for bad in ({"emissivity": 1.5}, {"emissivity": 0.0}, {"reflected_temperature": -300.0}):
        with pytest.raises(ConfigError, match=f"ir.{next(iter(bad))}"):
            read_ir(path, **bad)


def test_detection_from_content_not_suffix(tmp_path):
    path = write_flir(tmp_path / "recording.dat", _scene())
    assert detect_ir_format(path) == "flir"
    jpg = write_flir(tmp_path / "frame.bin", _scene(1)[0], jpeg=True)
    assert detect_ir_format(jpg) == "flir"


# ----------------------------------------------------------------------------
# configuration and ingest
# ----------------------------------------------------------------------------
@pytest.mark.parametrize("values,message", [
    ({"emissivity": 1.2}, "emissivity"), ({"emissivity": 0}, "emissivity"), ({"emissivity": "high"}, "emissivity"),
    ({"reflected_temperature": -274}, "reflected_temperature")])
def test_config_overrides_are_validated(values, message):
    from irdic.config import validate_section

    with pytest.raises(ConfigError, match=message):
        validate_section("ir", {"path": "x", **values}, schema_node="ir_source")
    ok = validate_section("ir", {"path": "x", "format": "flir", "emissivity": 0.9, "reflected_temperature": 21.0},
                          schema_node="ir_source")
    assert ok["emissivity"] == 0.9 and ok["reflected_temperature"] == 21.0


def test_ingest_seq_with_overrides(tmp_path):
    import xarray as xr

    from irdic.ingest.ir import ingest_ir

    t = _scene(4)
    times = [1.7e9 + k * 0.04 for k in range(4)]
    path = write_flir(tmp_path / "rec.seq", t, times=times, model="FLIR A655sc")
    out = ingest_ir(path, tmp_path / "ir.zarr", emissivity=0.9)
    with xr.open_zarr(out) as ds:
        p = dict(flir_parameters(), emissivity=0.9)
        np.testing.assert_allclose(ds["temperature"].values, counts_to_celsius(counts_of(t), p), atol=1e-4)
        np.testing.assert_allclose(ds["time"].values, [0, 0.04, 0.08, 0.12], atol=1e-6)
        assert list(ds["frame_index"].values) == [0, 1, 2, 3]
        assert ds.attrs["emissivity"] == 0.9 and ds.attrs["reflected_temp"] == 20.0
        assert ds.attrs["camera"] == "FLIR A655sc" and ds.attrs["planck_o"] == -7340.0
        assert '"emissivity": 0.9' in ds.attrs["irdic_parameters"]


def test_ingest_stores_the_readers_values_bit_for_bit(tmp_path):
    """The streamed ingest (plain arrays, no DataArray per frame) writes exactly what read_ir returns."""
    from irdic.ingest.ir import ingest_ir
    from irdic.store import open_store

    c = counts_of(_scene(5, 30, 40, seed=2))
    c[2, :3, :] = 0  # too cold to have a temperature: NaN pixels, counted, kept
    path = write_flir(tmp_path / "rec.seq", counts=c, times=[1.7e9 + 0.02 * k for k in range(5)])
    da = read_ir(path)
    ds = open_store(ingest_ir(path, tmp_path / "ir.zarr"), "ingest-ir")
    assert np.isnan(da.values[2, :3]).all()
    np.testing.assert_array_equal(ds["temperature"].values, da.values)  # NaN where NaN, every bit elsewhere
    np.testing.assert_array_equal(ds["u"].values, np.arange(40))
    np.testing.assert_array_equal(ds["v"].values, np.arange(30))
    np.testing.assert_allclose(ds["time"].values, da["time"].values, atol=1e-6)


def test_ingest_refuses_bad_series(tmp_path):
    from irdic.ingest.ir import ingest_ir
    from irdic.synthetic.writers import write_irb

    t = _scene()
    back = write_flir(tmp_path / "back.seq", t, times=[1.7e9, 1.7e9 + 1, 1.7e9 + 0.5])
    with pytest.warns(IrdicWarning), pytest.raises(DataError, match=r"back.seq\[2\].*does not come after"):
        ingest_ir(back, tmp_path / "a.zarr")
    sizes = write_flir(tmp_path / "sizes.seq", [t[0], t[1][:20]])
    with pytest.raises(DataError, match=r"sizes.seq: frame 1 is 32 x 20 px"):
        ingest_ir(sizes, tmp_path / "b.zarr")
    irb = write_irb(tmp_path / "x.irb", t, [0.0, 0.1, 0.2])
    with pytest.raises(ConfigError, match=r"ir.emissivity applies to FLIR radiometric files only.*x.irb is irb"):
        ingest_ir(irb, tmp_path / "c.zarr", emissivity=0.9)


@pytest.mark.slow
def test_demo_written_as_flir_ingests_to_the_same_temperatures(tmp_path):
    import xarray as xr

    from irdic.io.flir_planck import celsius_to_counts
    from irdic.ingest.ir import ingest_ir
    from irdic.synthetic.demo import FLIR_PARAMETERS, write_experiment
    from irdic.synthetic.experiments import experiment

    ex = experiment("tube", "tiny")
    files = write_experiment(tmp_path / "flir", ex, ir_format="flir")
    assert [f.name for f in files["ir"]] == ["tube.seq"]
    write_experiment(tmp_path / "irbis", ex)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", IrdicWarning)
        a = xr.open_zarr(ingest_ir(tmp_path / "flir" / "tube" / "ir", tmp_path / "a.zarr"))
        b = xr.open_zarr(ingest_ir(tmp_path / "irbis" / "tube" / "ir", tmp_path / "b.zarr"))
    assert a.sizes["u"] == ex.camera.width and a.sizes["v"] == ex.camera.height  # full-sensor frames
    np.testing.assert_allclose(a["time"].values, b["time"].values, atol=1e-9)
    tb = b["temperature"].values
    ta = a["temperature"].sel(u=b["u"], v=b["v"]).values  # the crop window at its sensor position
    p = flir_parameters(FLIR_PARAMETERS)
    half_count = 0.5 * 0.01 / (celsius_to_counts(tb + 0.01, p) - celsius_to_counts(tb, p))
    assert (np.abs(ta - tb) <= half_count + 5e-4 + 1e-5).all()  # + the IRBIS export's 3 decimals
    assert a.attrs["emissivity"] == 0.96 and a.attrs["distance"] == 0.45 and a.attrs["env_temp"] == 22.0


def test_folder_of_radiometric_jpegs_is_a_series(tmp_path):
    import imagecodecs
    import xarray as xr

    from irdic.ingest.ir import ingest_ir

    t = _scene(3)
    folder = tmp_path / "ir"
    folder.mkdir()
    for k in range(3):
        write_flir(folder / f"FLIR_{k:04d}.jpg", t[k], jpeg=True, encoding="png", times=[1.7e9 + 2.0 * k])
    (folder / "photo.jpg").write_bytes(imagecodecs.jpeg8_encode(np.zeros((8, 8), np.uint8)))  # a plain picture
    with xr.open_zarr(ingest_ir(folder, tmp_path / "ir.zarr")) as ds:
        assert ds.sizes["time"] == 3
        np.testing.assert_allclose(ds["time"].values, [0.0, 2.0, 4.0])
        assert np.abs(ds["temperature"].values - t).max() < 0.01
        assert list(ds["frame_index"].values) == [-1, -1, -1]  # one frame per file: no frame number
    # pictures have no frame numbers: a frame rate numbers them by their position
    with xr.open_zarr(ingest_ir(folder, tmp_path / "ir2.zarr", time_source="frame_rate", frame_rate=4.0)) as ds:
        np.testing.assert_allclose(ds["time"].values, [0.0, 0.25, 0.5])


@pytest.mark.slow
def test_radiometric_jpeg_as_calibration_target(tmp_path):
    """A target image saved by a FLIR camera calibrates like the same image as floats."""
    from irdic.calibration import calibrate_from_files
    from irdic.store import open_store
    from irdic.synthetic.camera import lab_camera
    from irdic.synthetic.target import open_book_target
    from irdic.synthetic.writers import write_markers

    lab = open_book_target(lab_camera())
    mpath = write_markers(tmp_path / "markers.txt", lab.markers.marker.values, lab.markers.x.values)
    jpg = write_flir(tmp_path / "target.jpg", lab.image.values, jpeg=True, encoding="png")
    ids, pix = lab.markers.marker.values, lab.truth.marker_pixel.values
    seeds = {int(ids[i]): pix[i].tolist() for i in (3, 17, 30, 47, 66, 79)}
    cal = open_store(calibrate_from_files(mpath, jpg, tmp_path / "cal.zarr", seeds=seeds, marker_radius_mm=1.6))
    assert cal.attrs["n_used"] == 84 and float(cal.rms_px) <= 0.05


def test_cli_ingest_with_overrides(tmp_path, capsys):
    import xarray as xr

    from irdic.cli import main

    path = write_flir(tmp_path / "a.seq", _scene(2))
    assert main(["ingest-ir", str(path), str(tmp_path / "ir.zarr"), "--emissivity", "0.9",
                 "--reflected-temperature", "25"]) == 0
    with xr.open_zarr(tmp_path / "ir.zarr") as ds:
        assert ds.attrs["emissivity"] == 0.9 and ds.attrs["reflected_temp"] == 25.0
    assert main(["ingest-ir", str(path), str(tmp_path / "ir2.zarr"), "--emissivity", "1.9"]) == 2
    assert "ir.emissivity: 1.9 is greater than the maximum of 1" in capsys.readouterr().err


# ----------------------------------------------------------------------------
# file variants not among the samples, against a decoder written here from the layout
# ----------------------------------------------------------------------------
def _png_by_hand(data: bytes) -> np.ndarray:
    """A 16-bit greyscale PNG decoded with zlib and the five row filters (samples as stored, big-endian)."""
    import zlib

    assert data[:8] == b"\x89PNG\r\n\x1a\n"
    pos, idat, w = 8, b"", None
    while pos < len(data):
        n, kind = struct.unpack_from(">I4s", data, pos)
        body = data[pos + 8:pos + 8 + n]
        if kind == b"IHDR":
            w, h, depth, colour = struct.unpack_from(">IIBB", body)
            assert (depth, colour) == (16, 0)
        elif kind == b"IDAT":
            idat += body
        pos += 12 + n
    flat, stride, bpp = zlib.decompress(idat), 2 * w, 2
    rows, prev = [], bytearray(stride)
    for r in range(h):
        kind, line = flat[r * (stride + 1)], bytearray(flat[r * (stride + 1) + 1:(r + 1) * (stride + 1)])
        for i in range(stride):
            a = line[i - bpp] if i >= bpp else 0
            b, c = prev[i], prev[i - bpp] if i >= bpp else 0
            p = a + b - c
            pred = [0, a, b, (a + b) // 2,
                    a if abs(p - a) <= abs(p - b) and abs(p - a) <= abs(p - c) else b if abs(p - b) <= abs(p - c)
                    else c][kind]
            line[i] = (line[i] + pred) & 0xFF
        rows.append(bytes(line))
        prev = line
    return np.frombuffer(b"".join(rows), ">u2").reshape(h, w)


def _blocks_by_hand(data: bytes) -> list[tuple[int, dict, bytes, bytes]]:
    """``(offset, {type: (subtype, offset, length)}, raw record, camera record)`` of each FFF block, chain order."""
    out, pos = [], 0
    while pos + 64 <= len(data) and data[pos:pos + 4] in (b"FFF\x00", b"AFF\x00"):
        hb = "<" if 100 <= struct.unpack_from("<I", data, pos + 0x14)[0] < 200 else ">"
        at, n = struct.unpack_from(hb + "II", data, pos + 0x18)
        recs, end = {}, at + 32 * n
        for k in range(n):
            kind, sub, _, _, off, length = struct.unpack_from(hb + "HHIIII", data, pos + at + 32 * k)
            if kind:
                recs.setdefault(kind, (sub, off, length))
                end = max(end, off + length)
        raw, cam = (data[pos + recs[t][1]:pos + recs[t][1] + recs[t][2]] for t in (0x01, 0x20))
        out.append((pos, recs, raw, cam))
        pos += end
    return out


def _temperatures_by_hand(data: bytes) -> list[np.ndarray]:
    """°C of every frame of an FFF chain, pixel by pixel through :func:`_raw2temp`."""
    frames = []
    for _pos, recs, raw, cam in _blocks_by_hand(data):
        rb = "<" if struct.unpack_from("<H", raw)[0] == 2 else ">"
        w, h = struct.unpack_from(rb + "HH", raw, 2)
        sub = recs[0x01][0]
        if sub in (1, 2):  # the record's byte order (its mark), as exiftool reads both subtypes
            counts = np.frombuffer(raw, rb + "u2", w * h, 32).reshape(h, w)
        else:
            assert sub == 3
            stored = _png_by_hand(raw[32:])
            cb = "<" if struct.unpack_from("<H", cam)[0] == 2 else ">"
            median, rng = struct.unpack_from(cb + "HH", cam, 0x338) if len(cam) >= 0x33e else (0, 0)
            both = (stored, stored.byteswap())
            inside = [np.mean(np.abs(c.astype(np.int64) - median) <= rng) for c in both]
            rough = [np.abs(np.diff(c.astype(float), axis=1)).mean() for c in both]
            if rng and max(inside) >= 0.5 and abs(inside[0] - inside[1]) >= 0.25:  # the displayed raw range
                counts = both[int(inside[1] > inside[0])]
            elif max(rough) > 4 * min(rough):  # the wrong order is rough
                counts = both[int(rough[1] < rough[0])]
            else:  # PNG samples in the record's byte order
                counts = both[int(rb == "<")]
        par = _camera_by_hand(cam, "<" if struct.unpack_from("<H", cam)[0] == 2 else ">")
        frames.append(np.array([[_raw2temp(float(c), **par) for c in row] for row in counts]))
    return frames


_VARIANT_PARAMS = {"emissivity": 0.87, "distance": 3.0, "reflected_k": 300.0, "atmosphere_k": 296.0,
                   "window_k": 291.0, "window_transmission": 0.9, "humidity": 0.65}


@pytest.mark.parametrize("variant", [
    dict(header_order="<", record_order=">"),  # big-endian raw image, subtype 2
    dict(header_order=">", record_order=">"),
    dict(header_order=">", record_order=">", subtype=1),  # subtype 1: big-endian raw (exiftool; not seen)
    dict(header_order="<", record_order="<", magic=b"AFF\x00"),
    dict(header_order=">", record_order=">", magic=b"AFF\x00"),
    dict(jpeg=True, header_order=">", record_order="<"),  # uncompressed raw in a radiometric JPEG
    dict(jpeg=True, header_order=">", record_order=">"),
    dict(jpeg=True, header_order="<", record_order="<"),
    dict(jpeg=True, encoding="png", header_order=">", record_order="<"),  # samples stored LE, as cameras do
    dict(jpeg=True, encoding="png", header_order=">", record_order=">", png_swap=False),  # stored as PNG says
    dict(jpeg=True, encoding="png", header_order="<", record_order=">", png_swap=False),
], ids=lambda v: "-".join(f"{k}={v[k]!r}" for k in v))
def test_variants_match_an_independent_decoder(tmp_path, variant):
    """Every pixel of each variant within 0.01 K of the decoder above, and of the scene within a count."""
    variant = dict(variant)
    magic = variant.pop("magic", None)
    jpeg = variant.get("jpeg", False)
    t = _scene(1, 20, 28, seed=3)[0] if jpeg else _scene(3, 20, 28, seed=3)
    path = write_flir(tmp_path / ("a.jpg" if jpeg else "a.seq"), t, params=_VARIANT_PARAMS, **variant)
    if magic is not None:
        data = bytearray(path.read_bytes())
        for pos, *_ in _blocks_by_hand(bytes(data)):
            data[pos:pos + 4] = magic
        path.write_bytes(bytes(data))
    data = path.read_bytes()
    by_hand = _temperatures_by_hand(_rjpeg_block(data) if jpeg else data)
    assert len(by_hand) == (1 if jpeg else 3)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        da = read_ir(path)
    got = da.values.reshape(len(by_hand), *t.shape[-2:])
    for k, want in enumerate(by_hand):
        assert np.abs(got[k] - want).max() < 0.01, k
    assert np.abs(got - t.reshape(got.shape)).max() < 0.02  # half a count of this camera: about 0.01 K
    assert da.attrs["emissivity"] == pytest.approx(0.87) and da.attrs["distance"] == 3.0
