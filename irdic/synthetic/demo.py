"""Write the demo experiment as real raw exports plus truth stores.

:func:`make_demo` writes::

    outdir/setup/markers.txt          83 marker centres (ID; x; y; z in mm, DIC frame)
    outdir/setup/target.txt           IRBIS text, full 1024 x 768 frame of the open-book target, 0.04 K noise
    outdir/setup/seeds.yaml           approximate pixel positions (true +- 2 px) of 8 markers
    outdir/setup/truth.zarr           true camera and per-marker truth
    outdir/<exp>/dic/<exp>_0_<k>.txt  ZEISS/ARAMIS nodemap of DIC stage k (relative time in s)
    outdir/<exp>/ir/<exp>_<n:05d>.txt IRBIS text crop export of IR frame n (n = position in the recording)
                                      (or outdir/<exp>/ir/<exp>.seq, one FLIR record, with ir_format="flir")
    outdir/<exp>/truth.zarr           every truth quantity on (time = DIC times, point)
    outdir/tube/machine.csv           the testing machine's record at 50 Hz on its own clock

Testing machine signals of the tube (linear elastic proxies of its
tension-torsion loading, see :class:`~irdic.synthetic.specimens.Tube`:
``F = E A u / L``, ``T = G J phi / L``): every nodemap has a ``SIGNALS``
section with ``force [N]``, ``displacement [mm]``, ``torque [N*m]``,
``angle [deg]`` (value elements) and ``Kraft [kN]``, ``Drehmoment [N*m]``
(analog inputs); stage 2 lacks ``torque`` (a missing signal).
``machine.csv`` is a German-locale export (``;``, decimal comma) with
``Zeit [s];Kraft [kN];Weg [mm];Drehmoment [N*m];Winkel [deg]`` every
0.02 s from machine time 0, which is ``MACHINE_CLOCK_OFFSET`` = 12.34 s
before the DIC trigger, to 1 s after the last stage: the configuration needs
``machine: {time_offset: -12.34}``.

IR exports: 3 decimals, ``StartPos`` = the crop window, ``ms`` = 1000 t +
1234.5 (ms since the recording started; t = 0 is the trigger shared with the
DIC), ``FrameIndex`` = n + 1, ``RecDate``/``RecTime`` of the frame. The
half-shell is written with TAB and ``.``; the tube as a German-locale export
(``;``, decimal comma, rows ending in ``;``) with one frame missing (dropped:
frame 17 at the demo scale, 5 at the tiny one).
DIC exports: 4 decimals, ``nan`` rows for failed facets and a few points
left out of some stages (see :mod:`irdic.synthetic.experiments`).

Everything is reproducible from ``seed``. Each of ``setup`` and ``<exp>`` is
written to a temporary folder and moved into place when complete.
"""

from __future__ import annotations

import datetime as _dt
import logging
import time as _time
from pathlib import Path

import numpy as np

from ..errors import ConfigError
from ..outputs import atomic_directory
from ..store import write_dataset
from ..validation import choice
from .camera import lab_camera
from .experiments import EXPERIMENTS, SCALES, Experiment, experiment
from .target import OpenBook, open_book_target

__all__ = ["make_demo", "write_setup", "write_experiment", "demo_book", "IR_MS_OFFSET", "MACHINE_CLOCK_OFFSET",
           "MACHINE_RATE", "MACHINE_COLUMNS"]

log = logging.getLogger(__name__)

#: ms of the trigger (t = 0) in the IR recording's clock
IR_MS_OFFSET = 1234.5
#: s of the trigger (t = 0) on the testing machine's clock (its record starts at machine time 0)
MACHINE_CLOCK_OFFSET = 12.34
#: samples per second of the machine record
MACHINE_RATE = 50.0
#: machine.columns of the configuration for the tube's machine.csv
MACHINE_COLUMNS = {"time": "Zeit [s]", "force": "Kraft [kN]", "displacement": "Weg [mm]",
                   "torque": "Drehmoment [N*m]", "angle": "Winkel [deg]"}
#: formats the demo can write its IR frames in
IR_FORMATS = ("irbis", "flir")
_REC_START = {"halfshell": _dt.datetime(2024, 5, 13, 10, 15, 40), "tube": _dt.datetime(2024, 5, 14, 14, 2, 10)}
_SETUP_TIME = _dt.datetime(2024, 5, 13, 9, 30, 5)
_IR_STYLE = {"halfshell": {"sep": "\t", "decimal": ".", "trailing_sep": False},
             "tube": {"sep": ";", "decimal": ",", "trailing_sep": True}}


def demo_book() -> OpenBook:
    """The demo's open-book target: the full 2 x 6 x 7 grid with one corner left
    unpainted, as on real targets, so that the open book is not symmetric and
    the markers can be assigned without seeds (83 markers)."""
    return OpenBook(unpainted=((1, 0, 6),))


def write_setup(outdir, *, camera=None, seed: int = 0, noise: float = 0.04) -> dict:
    """Write ``outdir/setup``: markers, target image, seeds and the camera truth.

    Returns
    -------
    dict
        Paths of the written files.
    """
    from .writers import write_irbis, write_markers

    camera = lab_camera() if camera is None else camera
    target = open_book_target(camera, noise=noise, seed=seed, book=demo_book())
    final = Path(outdir) / "setup"
    with atomic_directory(final) as tmp:
        tmp.mkdir(parents=True)
        order = np.argsort(target.markers.marker.values)  # DIC exports list markers by ID
        ids = target.markers.marker.values[order]
        write_markers(tmp / "markers.txt", ids, target.markers.x.values[order])
        write_irbis(tmp / "target.txt", target.image.values, ms=0.0, frame_index=1, rec_datetime=_SETUP_TIME,
                    sensor_size=(camera.width, camera.height), decimals=3, filename="target.irb",
                    parameters={"Distance": 0.45, "EnvTemp": 22.0, "Emissivity": 0.96})
        _write_seeds(tmp / "seeds.yaml", target, seed)
        write_dataset(target.truth, tmp / "truth.zarr", stage="synthetic-setup",
                      params={"seed": seed, "noise_K": noise, "camera": camera.describe()})
    return {"markers": final / "markers.txt", "target": final / "target.txt", "seeds": final / "seeds.yaml",
            "truth": final / "truth.zarr"}


def _write_seeds(path: Path, target, seed: int) -> None:
    book = target.book
    pick = [k for k in range(book.n_markers)
            if book.painted[k] and book.marker_row[k] in (0, book.n_rows - 1)
            and book.marker_col[k] in (0, 1, book.n_cols - 2, book.n_cols - 1)][:8]
    rng = np.random.default_rng([seed, 99])
    uv = target.truth.marker_centroid.sel(marker=book.ids[pick]).values + rng.uniform(-2.0, 2.0, (len(pick), 2))
    lines = ["# Approximate IR pixel positions of 8 calibration markers (true centre +- 2 px),",
             "# for users who prefer to seed the marker assignment by hand: paste under the",
             "# setup in config/config.yaml. Keys: marker IDs of setup/markers.txt; values:",
             "# [u, v] = pixel column and row (0-based, full sensor).",
             "seeds:"]
    for k, (u, v) in zip(pick, uv):
        lines.append(f"  {int(book.ids[k])}: [{u:.1f}, {v:.1f}]")
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")


def write_experiment(outdir, ex: Experiment, *, write_ir: bool = True, ir_format: str = "irbis") -> dict:
    """Write ``outdir/<ex.name>``: DIC nodemaps, IR exports and the truth store.

    ``ir_format``: ``"irbis"`` (one IRBIS text crop export per frame) or
    ``"flir"`` (one FLIR ``.seq``, see :func:`_write_flir_record`).

    Returns
    -------
    dict
        ``{"dic": [paths], "ir": [paths], "truth": path}``.
    """
    from .writers import write_irbis, write_nodemap

    name = ex.name
    final = Path(outdir) / name
    start = _REC_START[name]
    dic_files, ir_files = [], []
    with atomic_directory(final) as tmp:
        (tmp / "dic").mkdir(parents=True)
        (tmp / "ir").mkdir()
        x_undef = ex.x_dic[0]
        for k, t in enumerate(ex.dic_times):
            keep = ex.present[k]
            p = tmp / "dic" / f"{name}_0_{k}.txt"
            write_nodemap(p, ex.ids[keep], x_undef[keep], ex.x_dic[k][keep] - x_undef[keep], stage_index=k,
                          relative_time=float(t), reference_stage_index=0, stage_name=f"Stage {k}",
                          stage_date=start + _dt.timedelta(seconds=float(t)),
                          signals=_stage_signals(ex, k) if hasattr(ex.specimen, "axial_force") else None)
            dic_files.append(final / "dic" / p.name)
        if write_ir and ir_format == "flir":
            ir_files.append(final / "ir" / _write_flir_record(tmp / "ir" / f"{name}.seq", ex, start).name)
        elif write_ir:
            u0, v0, _, _ = ex.window
            for i, frame in enumerate(ex.ir_frames()):
                n = int(ex.ir_frame_numbers[i])
                ms = 1000.0 * float(ex.ir_times[i]) + IR_MS_OFFSET
                p = tmp / "ir" / f"{name}_{n:05d}.txt"
                write_irbis(p, frame.values, ms=ms, frame_index=n + 1,
                            rec_datetime=start + _dt.timedelta(milliseconds=ms), start_pos=(u0, v0),
                            sensor_size=(ex.camera.width, ex.camera.height), decimals=3,
                            filename=f"{name}.irb", parameters={"Distance": 0.45, "EnvTemp": 22.0,
                                                                "Emissivity": 0.96},
                            **_IR_STYLE[name])
                ir_files.append(final / "ir" / p.name)
        if hasattr(ex.specimen, "axial_force"):
            _write_machine(tmp / "machine.csv", ex)
        write_dataset(ex.truth(), tmp / "truth.zarr", stage="synthetic-truth",
                      params={"experiment": name, "scale": ex.scale, "ir_noise_K": ex.ir_noise,
                              "dic_noise_mm": ex.dic_noise, "seed": ex.seed, "ir_ms_offset": IR_MS_OFFSET,
                              "specimen": ex.specimen.describe()})
    return {"dic": dic_files, "ir": ir_files, "truth": final / "truth.zarr"}


#: object parameters of the demo's FLIR records (those of its IRBIS exports; kelvin as FLIR stores them)
FLIR_PARAMETERS = {"emissivity": 0.96, "distance": 0.45, "reflected_k": 295.15, "atmosphere_k": 295.15,
                   "window_k": 295.15}


def _write_flir_record(path: Path, ex: Experiment, start: _dt.datetime) -> Path:
    """The IR frames as one FLIR ``.seq`` of full-sensor frames.

    A FLIR frame holds no crop position, so the crop window is put into a
    full frame at its sensor position; the pixels around it are the room
    (22 °C) with the frames' noise. Each frame's time stamp is the
    recording start (UTC) + ``IR_MS_OFFSET`` + t, in whole milliseconds as
    FLIR stores them.
    """
    from .writers import write_flir

    u0, v0, w, h = ex.window
    t0 = start.replace(tzinfo=_dt.timezone.utc).timestamp() + round(IR_MS_OFFSET) / 1000.0
    times = [t0 + round(1000.0 * float(t)) / 1000.0 for t in ex.ir_times]

    def frames():
        for frame in ex.ir_frames():
            rng = np.random.default_rng([ex.seed, 31, int(frame.attrs["frame_number"])])
            full = 22.0 + rng.normal(0.0, ex.ir_noise, (ex.camera.height, ex.camera.width))
            full[v0:v0 + h, u0:u0 + w] = frame.values
            yield full

    return write_flir(path, frames(), times=times, params=FLIR_PARAMETERS, model="FLIR A655sc (irdic demo)")


def _stage_signals(ex: Experiment, k: int) -> list[tuple[str, str, float]]:
    """SIGNALS of DIC stage ``k``: English value elements, German analog inputs; stage 2 lacks the torque."""
    spec, t = ex.specimen, float(ex.dic_times[k])
    F, T = float(spec.axial_force(t)), float(spec.torque(t))
    u, phi = float(spec.axial_displacement(t)[0]), float(np.degrees(spec.twist(t)[0]))
    sig = [("force [N]", "value_element", F), ("displacement [mm]", "value_element", u),
           ("torque [N*m]", "value_element", T), ("angle [deg]", "value_element", phi),
           ("Kraft [kN]", "analog_input", F / 1000.0), ("Drehmoment [N*m]", "analog_input", T)]
    return [s for s in sig if not (k == 2 and s[0].startswith("torque"))]


def _write_machine(path: Path, ex: Experiment) -> None:
    """The machine record: German CSV, MACHINE_RATE Hz from machine time 0 to 1 s after the last stage."""
    spec = ex.specimen
    n = int(round((MACHINE_CLOCK_OFFSET + float(ex.dic_times[-1]) + 1.0) * MACHINE_RATE)) + 1
    t_machine = np.arange(n) / MACHINE_RATE
    t = t_machine - MACHINE_CLOCK_OFFSET  # the DIC clock
    cols = [t_machine, np.asarray(spec.axial_force(t)) / 1000.0, spec.axial_displacement(t)[0],
            np.asarray(spec.torque(t)), np.degrees(spec.twist(t)[0])]
    lines = ["Prüfmaschine;Demo Zug-Torsion", "Messrate [Hz];" + f"{MACHINE_RATE:g}".replace(".", ","), "",
             ";".join(MACHINE_COLUMNS.values())]
    fmt = ";".join(["%.3f", "%.9f", "%.9f", "%.9f", "%.9f"])
    lines += [(fmt % tuple(row)).replace(".", ",") for row in np.column_stack(cols).tolist()]
    path.write_text("\r\n".join(lines) + "\r\n", encoding="cp1252")


def make_demo(outdir, *, scale: str = "demo", ir_noise: float = 0.05, dic_noise: float = 0.005, seed: int = 0,
              experiments=EXPERIMENTS, write_ir: bool = True, ir_format: str = "irbis") -> dict:
    """Write the synthetic demo experiment(s) as raw exports plus truth.

    Parameters
    ----------
    outdir : path-like
        Output folder (created; ``setup`` and each experiment's folder are
        replaced as a whole).
    scale : {"tiny", "demo", "paper"}
        ``tiny``: a few frames and ~270 points per experiment (workflow tests,
        ~2 s); ``demo``: half-shell 30 s and tube 10 s, ~1,600 points
        (~10 s, ~75 MB); ``paper``: ~10,000 points and 500 IR frames per
        experiment (minutes and ~0.5 GB of IR text; consider
        ``write_ir=False`` and the in-memory generators).
    ir_noise : float
        IR pixel noise (K).
    dic_noise : float
        DIC coordinate noise (mm).
    seed : int
        Seed of all noise and defects.
    experiments : sequence of {"halfshell", "tube"}
        Which experiments to write.
    write_ir : bool
        Write the IR frame exports (False: only DIC and truth).
    ir_format : {"irbis", "flir"}
        IR exports as IRBIS text files (one per frame, crop window) or as
        one FLIR ``.seq`` per experiment (full-sensor frames of raw counts).

    Returns
    -------
    dict
        ``{"setup": {...}, "halfshell": {...}, "tube": {...}}`` of written paths.
    """
    choice(scale, "scale", SCALES)
    choice(ir_format, "ir_format", IR_FORMATS)
    if isinstance(experiments, str):
        experiments = (experiments,)
    experiments = tuple(experiments)
    if not experiments:
        raise ConfigError("`experiments` is empty; expected some of 'halfshell', 'tube'")
    for e in experiments:
        choice(e, "experiments", EXPERIMENTS)
    out = Path(outdir)
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise ConfigError(f"cannot create the demo folder {out}: {exc.strerror}") from exc
    t0 = _time.perf_counter()
    result = {"setup": write_setup(out, camera=lab_camera(), seed=seed)}
    log.info("demo setup written to %s (%.1f s)", out / "setup", _time.perf_counter() - t0)
    for name in experiments:
        t1 = _time.perf_counter()
        ex = experiment(name, scale, ir_noise=ir_noise, dic_noise=dic_noise, seed=seed)
        result[name] = write_experiment(out, ex, write_ir=write_ir, ir_format=ir_format)
        log.info("demo %s (%s) written to %s (%.1f s)", name, scale, out / name, _time.perf_counter() - t1)
        nums = np.asarray(ex.ir_frame_numbers)
        for k in sorted(set(range(int(nums.min()), int(nums.max()) + 1)) - set(nums.tolist())):
            # a deliberate defect: the ingest stage's gap warning is expected, not a fault of the run
            log.warning("demo %s: IR frame %d is left out on purpose (a dropped frame, as real recordings have); "
                        "ingest-ir will warn about the gap in the IR time axis: expected for the demo", name, k)
    return result
