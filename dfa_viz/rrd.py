"""Writing .rrd files: a stream whose file holds the same content for the same calls, written
atomically, and a blueprint sent without leaving a stream behind. The run recorder, the
sweep, the experiment's curves and the study's answers all write through these."""

from __future__ import annotations

import uuid
from datetime import timedelta
from pathlib import Path

import rerun as rr
import rerun.blueprint as rrb

from sim.core import files

APP_ID = "dfa"


def recording_id(world: str, shift: str, seed: int) -> uuid.UUID:
    """The same run always gets the same recording id (reproducible files)."""
    return uuid.uuid5(uuid.NAMESPACE_URL, f"dfa/{world}/{shift}/{seed}")


def new_stream(rid: uuid.UUID, *, app_id: str = APP_ID) -> rr.RecordingStream:
    """A stream whose file holds the same content for the same calls, on any machine.

    No log time or tick columns; rows are cut into chunks by size and row count, never by a
    wall-clock tick, so the chunks are the same too. (Rerun's own row and chunk ids are
    time-based: two files of one run differ in those bytes only.)
    """
    # Rerun keeps every stream dropped so far (its two threads and every row it logged) until
    # this sweep, which rr.init also does; a server writes a file per action, so sweep here.
    rr.bindings.flush_and_cleanup_orphaned_recordings()
    rec = rr.RecordingStream(
        app_id,
        recording_id=rid,
        send_properties=False,
        batcher_config=rr.ChunkBatcherConfig(
            flush_tick=timedelta(days=1), flush_num_bytes=1 << 20, flush_num_rows=4096
        ),
    )
    rec.set_log_time_enabled(False)
    rec.set_log_tick_enabled(False)
    return rec


class RrdFile:
    """An .rrd written atomically: logged into memory, written whole to a temporary file beside
    `path` and moved into place by `close()`; `close(keep=False)` (or an exception inside
    `with`) leaves `path` as it was. A write that fails (a full disk) raises an OSError naming
    `path`, and leaves `path` as it was.

    The stream goes to rerun's binary stream, not its file sink (`rec.save`): once a write to
    its file fails, rerun 0.41's file sink makes `flush()` and `disconnect()` wait forever.
    A recording is a few megabytes; the bytes are held until `close()`.
    """

    def __init__(self, path: str | Path, rid: uuid.UUID, *, app_id: str = APP_ID) -> None:
        self.path = Path(path)
        self.rec = new_stream(rid, app_id=app_id)
        self.stream = rr.binary_stream(self.rec)

    def close(self, *, keep: bool = True) -> Path:
        self.rec.flush()
        self.rec.disconnect()
        data = self.stream.read(flush=True) or b""  # the whole file, its footer included
        if keep:
            files.write_bytes(self.path, data)
        return self.path

    def __enter__(self) -> rr.RecordingStream:
        return self.rec

    def __exit__(self, kind, value, tb) -> None:
        self.close(keep=kind is None)


def send_blueprint(rec: rr.RecordingStream, bp: rrb.Blueprint) -> None:
    """`rec.send_blueprint(bp)` (active and default), and the blueprint's stream closed after.

    Rerun 0.41's own send_blueprint logs the blueprint to a stream of its own that is never
    released (two threads and half a megabyte per call); disconnecting that stream frees it.
    """
    stream = rr.RecordingStream._from_native(
        rr.bindings.new_blueprint(
            application_id=rec.get_application_id(),
            make_default=False,
            make_thread_default=False,
            default_enabled=True,
        )
    )
    try:
        stream.set_time("blueprint", sequence=0)
        bp.to_blueprint()._log_to_stream(stream)
        storage = stream.memory_recording().storage
        rr.bindings.send_blueprint(storage, True, True, recording=rec.to_native())
    finally:
        stream.disconnect()
