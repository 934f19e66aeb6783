"""An .rrd read back with rerun's own reader, for tests: each entity's chunks as columns."""

from __future__ import annotations

import rerun as rr


def chunks(path) -> dict[str, list[dict]]:
    """entity path -> its chunks, each as {column name: values}."""
    by_entity: dict[str, list[dict]] = {}
    for chunk in rr.chunk.RrdReader(path).store().stream():
        by_entity.setdefault(str(chunk.entity_path), []).append(chunk.to_record_batch().to_pydict())
    return by_entity


def column(entity_chunks: list[dict], name: str) -> list:
    """Every value of one column over an entity's chunks, in order."""
    return [v for c in entity_chunks if name in c for v in c[name]]
