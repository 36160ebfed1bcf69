"""A chunk of an irdic store that cannot be decoded is named, with its store.

zarr decodes chunks far from the code that asked for the values (an event
loop, a batch of chunks), and a damaged chunk of the same length as the
good one (a bit flip, a block of zeros from a failing disk) ends in a bare
``RuntimeError: error during blosc decompression``. The codec pipeline
below is zarr's own, with one difference: a chunk of a store opened by
:func:`irdic.store.open_store` that fails to decode raises
:class:`~irdic.errors.DataError` naming the store, the variable and the
chunk. Chunks of other stores fail as zarr makes them fail.
"""

from __future__ import annotations

import zarr
from zarr.core.codec_pipeline import BatchedCodecPipeline
from zarr.registry import register_pipeline

from .errors import DataError, IrdicError

__all__ = ["NamingCodecPipeline", "install"]


class NamingCodecPipeline(BatchedCodecPipeline):
    """zarr's batched codec pipeline; decoding errors in irdic's stores name the chunk."""

    async def read_batch(self, batch_info, out, drop_axes=()):
        batch_info = list(batch_info)
        try:
            await super().read_batch(batch_info, out, drop_axes)
        except IrdicError:
            raise
        except Exception as exc:
            getter = batch_info[0][0] if batch_info else None
            store = getattr(getter, "store", None)
            if not getattr(store, "irdic_checked", False):
                raise
            keys = [str(b[0].path) for b in batch_info]
            arr = keys[0].rpartition("/c")[0]
            more = f" (or one of the {len(keys)} chunks read with it)" if len(keys) > 1 else ""
            raise DataError(f"{store.root}: variable {arr!r}: chunk {keys[0]}{more} cannot be decoded "
                            f"({type(exc).__name__}: {exc}); the store is damaged, copy it again or run the "
                            "stage that writes it again") from exc


def install() -> None:
    """Make zarr build :class:`NamingCodecPipeline` for every array it opens (idempotent)."""
    path = f"{NamingCodecPipeline.__module__}.{NamingCodecPipeline.__qualname__}"
    if zarr.config.get("codec_pipeline.path") != path:
        register_pipeline(NamingCodecPipeline)
        zarr.config.set({"codec_pipeline.path": path})
