"""Writers of the raw export formats that :mod:`irdic.io` reads.

They produce the demo's files and the tests' fixtures: each writes exactly
the layout its reader documents, so that a round trip checks the reader
against known values.
"""

from .dice import write_dice
from .flir import write_flir
from .irb import write_irb
from .irbis import write_irbis
from .markers import write_markers
from .nodemap import write_nodemap
from .vic import write_vic

__all__ = ["write_dice", "write_flir", "write_irb", "write_irbis", "write_markers", "write_nodemap", "write_vic"]
