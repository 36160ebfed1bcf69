"""Synthetic experiments with closed-form truth, written as real raw exports.

This package is the demo a new user runs and the truth the rest of irdic is
tested against; it does not use irdic's own calibration or interpolation code.

- :mod:`.camera`: the true IR camera (:class:`TrueCamera`, :func:`lab_camera`:
  the paper's 1024 x 768 px, f = 1754.4 px camera, 450 mm from the specimen,
  17.5 deg off the DIC z axis).
- :mod:`.target`: the open-book calibration target (84 markers), rendered
  exactly under perspective (:func:`open_book_target`).
- :mod:`.specimens`: the heated half-shell and the tension-torsion tube,
  with closed-form kinematics, temperature and all derivatives.
- :mod:`.render`: ray casting of IR frames and of the continuous IR field.
- :mod:`.truth`: every truth quantity at DIC points and times.
- :mod:`.experiments`: in-memory experiments (:func:`halfshell_experiment`,
  :func:`tube_experiment`) at scales ``tiny``, ``demo``, ``paper``.
- :mod:`.demo`: :func:`make_demo` writes it all as IRBIS text, ARAMIS
  nodemaps, a marker file and zarr truth stores.
- :mod:`.family`: a family of scenes drawn from a seed (:func:`family.draw`)
  and a fixed, named set (:func:`family.member`): other geometries
  (:mod:`.shapes`), motions and temperature patterns (:mod:`.patterns`),
  noise, point densities and camera poses, each a :class:`~.family.Scene`
  with its truth (:class:`~.scene.SceneSpecimen`).

Coordinates: the world frame is the DIC frame (mm), y up, z towards the DIC
cameras; pixels ``u`` = column, ``v`` = row, 0-based, centres on integers.
"""

from .camera import IR_F, IR_SIZE, TrueCamera, lab_camera, look_at
from .demo import make_demo, write_experiment, write_setup
from .experiments import EXPERIMENTS, SCALES, Experiment, experiment, halfshell_experiment, tube_experiment
from .render import FrameRenderer, field, pixel_derivatives, visibility
from .specimens import HalfShell, Hit, Specimen, Tube
from .target import OpenBook, TargetImage, camera_dataset, open_book_target
from .truth import point_truth
from . import family
from .scene import SceneSpecimen

__all__ = [
    "TrueCamera", "look_at", "lab_camera", "IR_F", "IR_SIZE",
    "OpenBook", "TargetImage", "open_book_target", "camera_dataset",
    "Specimen", "HalfShell", "Tube", "Hit", "SceneSpecimen", "family",
    "FrameRenderer", "field", "pixel_derivatives", "visibility",
    "point_truth",
    "Experiment", "experiment", "halfshell_experiment", "tube_experiment", "SCALES", "EXPERIMENTS",
    "make_demo", "write_setup", "write_experiment",
]
