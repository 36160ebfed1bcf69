"""The raw series into stores: which files, their time axis, the DIC points and the IR frames.

Modules
-------
* :mod:`.inputs`: the files of a series (folder, glob or list) and the time
  axis they give (from the files or a frame rate).
* :mod:`.dic`: a series of DIC stage exports -> ``dic.zarr`` (points matched
  between stages, the testing machine signals of the exports).
* :mod:`.ir`: a series of IR exports -> ``ir.zarr``, streamed frame by frame.

The readers of the formats are :mod:`irdic.io`. The initialiser imports none
of its modules, so that each ingest stage's code hash covers only its own.
"""
