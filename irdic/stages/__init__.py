"""The pipeline's stages, one module each, each with one entry ``run(inputs, outputs, **params)``.

``inputs`` and ``outputs`` map names to paths (a mapping or Snakemake's
``snakemake.input``/``snakemake.output``); ``params`` are the stage's
section of the validated configuration (absent keys take the schema's
defaults, :mod:`irdic.parameters`); ``log`` (a log file) and
``threads`` (CPU threads, applied once at entry) are common to all. The
Snakemake scripts, :func:`irdic.pipeline.run` and the command line all call
these entries.

============== ============================================== ==================================
module          inputs                                         outputs
============== ============================================== ==================================
demo            (none)                                         manifest
ingest_ir       source (IR exports)                            store (ir.zarr)
ingest_dic      source (DIC exports)                           store (dic.zarr)
ingest_machine  source (machine record)                        store (machine.zarr)
calibrate       markers, target                                store (calibration.zarr), figure
couple          dic, ir, calibration                           store (points.zarr)
fields          points, calibration, dic?, machine?            store (fields.zarr)
figures         points, fields?                                {figure name: PNG}
export          points, fields?                                paraview, csv
============== ============================================== ==================================

An entry reads its stores, calls the domain packages (:mod:`irdic.ingest`,
:mod:`irdic.calibration`, :mod:`irdic.coupling`, :mod:`irdic.fields`, ...)
and writes its store; the domain never imports a stage. This package imports
none of its modules, so that each stage's code hash (:mod:`irdic.codehash`)
covers only what that stage imports.
"""
