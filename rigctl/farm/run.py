"""``rigctl process``: a take on a Dask cluster (an existing scheduler, or a local cluster of worker processes)
as chunks of consecutive frame sets, each chunk one task running the take-level pipeline
(:mod:`rigctl.depth.pipeline`), outputs in ``rigctl depth``'s layout under ``DIR/depth``, a ledger in
``DIR/process.json`` that makes a stopped run safe to run again. The take's range is decided first (one task),
recorded in the ledger and handed to every chunk, so all chunks search the same range and the outputs are the
bytes ``rigctl depth`` writes over the same chunks.

The client reads only the take's manifest and indexes (to list the frame sets); workers read the frames
themselves from storage every one of them sees, so the scheduler carries paths and small dicts, never images.
A worker that dies takes its task back to the scheduler, which runs it elsewhere (Dask's
``distributed.scheduler.allowed-failures``); a frame that fails is recorded and the others go on.
"""

from __future__ import annotations

import hashlib
import json
import logging
import math
import re
import shutil
import time
import uuid
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

from pydantic import BaseModel, ConfigDict

from rigctl.depth.export import DEFAULT_FORMATS, PARTIAL_PREFIX, Exporter, check_room, frame_name
from rigctl.depth.options import DepthOptions
from rigctl.depth.pipeline import ChunkEnd, chunks, settle
from rigctl.depth.take_range import RangeDecision, SearchRounds, SearchState, hull
from rigctl.errors import DeviceError, ParameterError, RigctlError
from rigctl.farm.frame import ChunkJob, is_rectified, one_line, run_chunk, take_range
from rigctl.farm.ledger import FrameEntry, Ledger, RunSettings
from rigctl.farm.wire import MAX_MESSAGE_BYTES, bounded_messages

if TYPE_CHECKING:
    from rigctl.take.manifest import Manifest

log = logging.getLogger(__name__)

_SCHEDULER = re.compile(
    r"tcp://(?P<host>\[[0-9A-Fa-f:.]+\]|[A-Za-z0-9](?:[A-Za-z0-9.-]*[A-Za-z0-9])?):(?P<port>\d{1,5})"
)


def scheduler_url(text: str) -> str:
    """A scheduler address ``tcp://HOST:PORT``; anything else is refused with one line."""
    m = _SCHEDULER.fullmatch(text.strip())
    if m is None or not 0 < int(m["port"]) < 65536:
        raise ParameterError(f"--scheduler: expected tcp://HOST:PORT (port 1-65535), got {text!r}")
    return text.strip()


@dataclass
class FarmOptions:
    take: Path
    out: Path
    depth: DepthOptions = field(default_factory=DepthOptions)
    calibration: Path | None = None
    frames: range | None = None  # --frames as asked, checked against the take's complete frame sets
    redo: bool = False
    scheduler: str | None = None
    workers: int = 2
    memory_limit: str | int = "auto"
    formats: tuple[str, ...] = DEFAULT_FORMATS  # what each frame set writes per camera (rigctl.depth.export)


@dataclass
class Status:
    """The counts a run reports as it goes (``rigctl process`` shows them with rate and time remaining)."""

    total: int  # frame sets to compute, every round's
    skipped: int = 0
    done: int = 0
    failed: int = 0
    round: int = 1  # the take's range widened in round 1: every chunk is computed again from it (``settle``)
    round_total: int = 0  # the frame sets of this round
    round_start: int = 0  # ``finished`` when it started

    @property
    def finished(self) -> int:
        return self.done + self.failed

    @property
    def round_finished(self) -> int:
        return self.finished - self.round_start


@dataclass
class Work:
    """What a run is to do: every chunk of the frame sets asked for, the frame sets done whose files are whole,
    the ledger. A chunk is computed whole (its state runs through it) unless every frame set of it is whole and
    was computed from the search state the take's chunks start from now (:meth:`todo`)."""

    chunks: list[list[int]]
    whole: set[int]
    ledger: Ledger
    redo: bool = False

    def todo(self, state: SearchState) -> tuple[list[list[int]], list[int]]:
        """The chunks to compute from ``state`` and the frame sets skipped."""
        todo: list[list[int]] = []
        skipped: list[int] = []
        for chunk in self.chunks:
            entries = [self.ledger.frames.get(frame_name(n)) for n in chunk]
            done = all(n in self.whole for n in chunk) and all(e is not None and e.start == state for e in entries)
            if done and not self.redo:
                skipped += chunk
            else:
                todo.append(chunk)
        return todo, skipped


def run_settings(options: FarmOptions, manifest: Manifest) -> RunSettings:
    """What the run's outputs depend on besides the chunking (recorded in the ledger, checked by a rerun)."""
    opt = options.depth
    if opt.disparity_range is not None:
        plan = f"disparity range {opt.disparity_range[0]}..{opt.disparity_range[1]} px"
    elif opt.near_m is not None:
        plan = f"--near {opt.near_m} --far {opt.far_m if opt.far_m is not None else math.inf}"
    else:
        plan = "no plan (--near/--far)"
    # the manifest as a model, so the YAML's spelling does not count; the crew's verdict changes no frame
    identity = manifest.model_dump(mode="json", exclude={"verdict", "notes"})
    calibration = options.calibration
    return RunSettings(
        take=str(options.take.resolve()),
        take_sha256=hashlib.sha256(json.dumps(identity, sort_keys=True).encode()).hexdigest(),
        calibration=str(calibration.resolve()) if calibration else None,
        calibration_sha256=hashlib.sha256(calibration.read_bytes()).hexdigest() if calibration else None,
        preset=opt.preset,
        plan=plan,
        margin_px=opt.margin_px,
        cameras=sorted(opt.cameras) if opt.cameras else None,
        key=opt.key,
        temporal=opt.temporal,
        layout=Exporter.layout,
        colour=Exporter.colour,
    )


def check_settings(ledger: Ledger, settings: RunSettings, chunk: int, warmup: int) -> None:
    """Refuse, in one line, a run whose settings are not those the ledger's frame sets (or its range) were
    computed with: they would be kept as this run's results. --redo does not lift it (the frame sets it does not
    redo would stay the old settings'): a new --out does."""
    data = ledger.data
    if data.settings is None:
        if data.frames or data.range is not None:
            raise ParameterError(
                f"{ledger.path}: written by an older rigctl that did not record the take and settings its frame sets "
                "were computed with, so this run cannot be checked against them: use a new --out"
            )
        return
    differ = data.settings.differences(settings)
    if data.chunk is not None and (data.chunk, data.warmup) != (chunk, warmup):
        differ.append(f"--chunk {data.chunk} --warmup {data.warmup}, asked --chunk {chunk} --warmup {warmup}")
    if differ:
        raise ParameterError(f"{ledger.path}: computed with {'; '.join(differ)}: use a new --out for this run")


def frames_to_do(options: FarmOptions) -> Work:
    """The chunks to compute and the frame sets already done, checked on the client."""
    from rigctl.take.framesets import check_frames
    from rigctl.take.reader import TakeReader

    options.depth.check()  # what needs no take: refused before a cluster or a folder (the CLI checked already)
    take = options.take
    if not (take / "take.yaml").exists():
        raise ParameterError(f"{take}: not a take (no take.yaml)")
    rectified = is_rectified(take)
    if not rectified and options.calibration is None:
        raise ParameterError(f"{take}: not rectified: give --calibration (from rigctl calibrate) to rectify on the way")
    if rectified and options.calibration is not None:
        raise ParameterError(f"{take}: already rectified; --calibration is only for takes that are not")
    reader = TakeReader(take)
    if options.calibration is not None:
        from rigctl.rectification.rectify import rectifier_for_take

        rectifier_for_take(reader, options.calibration)  # refuses a calibration of other cameras or size now
    cams = options.depth.cameras
    unknown = [c for c in cams or () if c not in reader.names]
    if unknown:
        raise ParameterError(f"--cameras: no camera {', '.join(unknown)} in {take} (it has {', '.join(reader.names)})")
    numbers = [s.number for s in reader.complete_sets()]
    numbers = check_frames(options.frames, numbers, take)
    if not numbers:
        raise ParameterError(f"{take}: the take has no complete frame set")
    ledger = Ledger(options.out)
    settings = run_settings(options, reader.manifest)
    check_settings(ledger, settings, options.depth.chunk, options.depth.warmup)
    ledger.data.settings = settings
    ledger.data.chunk, ledger.data.warmup = options.depth.chunk, options.depth.warmup
    depth_dir = options.out / "depth"
    names = list(cams or reader.names)
    files = [f"{c}.{ext}" for c in names for ext in options.formats]  # a frame set is whole with what is asked
    whole = {n for n in numbers if ledger.whole(frame_name(n), depth_dir / frame_name(n))
             and all((depth_dir / frame_name(n) / f).exists() for f in files)}  # fmt: skip
    sets = sum(len(c) for c in chunks(numbers, options.depth.chunk) if options.redo or not whole.issuperset(c))
    if sets:  # a chunk is written whole
        check_room(options.out, sets, len(names), (reader.width, reader.height), options.formats)
    return Work(chunks(numbers, options.depth.chunk), whole, ledger, options.redo)


class ProcessSummary(BaseModel):
    """What ``rigctl process`` did (``--json`` prints it)."""

    model_config = ConfigDict(extra="forbid")

    take: str
    out: str
    ledger: str
    frames: int
    chunks: int  # chunks this run computed, each once (it ran again from a widened range: chunks_recomputed)
    computed: int  # frame sets this run computed, each once, done in its last pass
    failed: int
    skipped_done: int
    failed_frames: dict[str, str]
    frames_by_worker: dict[str, int]  # frame sets by the worker of their last pass
    range: RangeDecision | None
    search: SearchRounds | None  # how the take's range settled: the state every chunk started from, the rounds
    widenings: int  # widenings of the range within the chunks of the last round (each in the frame's report)
    bound_hit_pixels: int  # summed over the frame sets computed by this run
    seconds: float
    compute_seconds: float  # from the first task submitted to the last result (no cluster start)
    frames_per_second: float  # frame sets computed (each once) a second of compute
    # the repeat passes (a chunk widened the take's range, every chunk ran again): computations beyond the first
    recomputed: int = 0
    chunks_recomputed: int = 0


def default_memory_limit(take: Path, cameras: int | None) -> int:
    """The worker memory bound for a take's frame size (bytes): see :func:`worker_memory_bytes`."""
    from rigctl.take.reader import TakeReader

    reader = TakeReader(take)
    return worker_memory_bytes(reader.width, reader.height, cameras or len(reader.names))


# A worker's peak resident memory: a fixed part (interpreter, OpenCV, Dask) and a part per pixel and camera,
# fitted from a chunk's later frame sets as a worker runs them (``benchmarks/chunk_memory.py``: the moving
# realistic presenter, nine cameras, best, the stabiliser's state carried; README "Memory"): 0.87, 1.12 and
# 2.52 GiB at 960x540, 1920x1080 and 3840x2160 after issue 24's memory steps, about 27 B a pixel and camera
# between the two larger sizes. The bound is 1 GB + 36 B, 25 to 39 % above the measured peaks;
# the worker limit is that with a margin of 25 %, and Dask pauses a worker at 80 % of its limit (the bound)
# and restarts it at 95 %. It was 600 MB + 74 B (7.7 GB a 4K worker) while a chunk peaked at 4.9 GiB.
BASE_BYTES = 1.0e9
BYTES_PER_CAMERA_PIXEL = 36.0
MARGIN = 1.25


def worker_memory_bytes(width: int, height: int, cameras: int) -> int:
    return int(MARGIN * (BASE_BYTES + BYTES_PER_CAMERA_PIXEL * width * height * cameras))


@contextmanager
def dask_client(options: FarmOptions) -> Iterator[Any]:
    """A client of the given scheduler, or of a local cluster of ``workers`` processes with one thread each."""
    from distributed import Client, LocalCluster

    if options.scheduler:
        what = f"--scheduler {options.scheduler}"
        with bounded_messages() as refusals:
            try:
                client = Client(options.scheduler, timeout="10s")
            except (OSError, TimeoutError) as exc:
                refused = refusals.first(what, MAX_MESSAGE_BYTES)
                if refused:
                    raise DeviceError(refused) from None
                raise ParameterError(f"{what}: cannot reach it ({one_line(exc)})") from None
            try:
                yield client
            except Exception:
                refused = refusals.first(what, MAX_MESSAGE_BYTES)
                if refused:  # the connection was dropped on a message too large: that is the error
                    raise DeviceError(refused) from None
                raise
            finally:
                client.close()
        return
    if options.workers < 1:
        raise ParameterError(f"--workers must be at least 1, got {options.workers}")
    limit = options.memory_limit
    if limit == "auto":
        limit = default_memory_limit(options.take, len(options.depth.cameras or ()) or None)
    from rigctl.allocator import dask_workers_allocate_as_depth
    from rigctl.farm.quiet import quiet_nannies

    with (
        dask_workers_allocate_as_depth(),  # not Dask's MALLOC_TRIM_THRESHOLD_ (rigctl.allocator)
        quiet_nannies(),  # an interrupted run: Dask's shutdown notices kept off stderr (rigctl.farm.quiet)
        LocalCluster(
            n_workers=options.workers,
            threads_per_worker=1,
            processes=True,
            memory_limit=limit,
            host="127.0.0.1",
            dashboard_address="127.0.0.1:0",  # None meant port 8787: busy, a 4-line UserWarning on stderr
            scheduler_kwargs={"dashboard": False},
            preload=["rigctl.farm.quiet"],  # each worker: SIGINT ignored, its shutdown notice dropped
        ) as cluster,
        Client(cluster) as client,
    ):
        yield client


def process_take(
    options: FarmOptions,
    progress: Callable[[Status], None] | None = None,
    clock: Callable[[], float] = time.monotonic,
) -> ProcessSummary:
    """Decide the take's range (or reuse the ledger's), then run every chunk still to do."""
    work = frames_to_do(options)
    ledger = work.ledger
    depth_dir = options.out / "depth"
    status = Status(total=0)
    failed: dict[str, str] = {}
    computed: dict[str, FrameEntry] = {}  # this run's last result of every frame set
    t0 = clock()
    compute_seconds = 0.0
    known = ledger.data.search.state if ledger.data.search is not None and ledger.data.range is not None else None
    if known is not None and ledger.data.reached is not None:
        known = hull([known, ledger.data.reached])  # a round was cut short: its chunks widened the range
    todo, skipped = work.todo(known) if known is not None else (work.chunks, [])
    chunks_run = 0  # runs of a chunk, each round's
    chunks_seen: set[tuple[int, ...]] = set()
    if todo:
        from distributed import as_completed

        take = str(options.take.resolve())
        calibration = str(options.calibration.resolve()) if options.calibration else None
        with dask_client(options) as client:
            t_compute = clock()
            run_id = uuid.uuid4().hex[:8]
            decision = ledger.data.range
            plan = options.depth.near_m is not None or options.depth.disparity_range is not None
            # a measured range is kept across runs (every chunk must search the same one); a plan is cheap to
            # turn into a range again, and may have been given since
            if decision is None or options.redo or plan or decision.planned:
                fut = client.submit(take_range, take, calibration, options.depth, key=f"rigctl-range-{run_id}")
                new = fut.result()
                if isinstance(new, RigctlError):  # refused on the worker: our one line, before any folder
                    raise new
                if new != decision or options.redo:  # the chunks start from the new range
                    ledger.data.search = ledger.data.reached = None
                decision = ledger.data.range = new
            if ledger.data.search is None:
                ledger.data.search = SearchRounds(state=decision.start(), rounds=0, settled=False)
            start = ledger.data.search.state
            if ledger.data.reached is not None:
                start = hull([start, ledger.data.reached])
            ledger.save()
            depth_dir.mkdir(parents=True, exist_ok=True)
            for stale in depth_dir.glob(PARTIAL_PREFIX + "*"):  # left by a run that was stopped mid-write
                shutil.rmtree(stale, ignore_errors=True)

            def run_round(state: SearchState, round_: int) -> list[ChunkEnd]:
                """The chunks not yet computed from ``state``; the ledger notes where each one's search ended."""
                nonlocal skipped, chunks_run
                assert ledger.data.search is not None
                if ledger.data.search.state != state:
                    ledger.data.reached = None
                ledger.data.search = ledger.data.search.model_copy(
                    update={"state": state, "rounds": round_, "settled": False}
                )
                ledger.save()
                todo, now_skipped = work.todo(state)
                if round_ == 1:
                    skipped = now_skipped
                status.round, status.round_start = round_, status.finished
                status.round_total = sum(len(c) for c in todo)
                status.total += status.round_total
                chunks_run += len(todo)
                chunks_seen.update(tuple(c) for c in todo)
                futures = {}
                for chunk in todo:
                    job = ChunkJob(take, str(depth_dir.resolve()), tuple(chunk), options.depth, decision, state,
                                   calibration, options.formats)  # fmt: skip
                    key = f"rigctl-chunk-{frame_name(chunk[0])}-r{round_}-{run_id}"
                    futures[client.submit(run_chunk, job, key=key, pure=False)] = chunk
                if progress:
                    progress(status)
                ends: list[ChunkEnd] = []
                for fut in as_completed(futures):
                    chunk = futures[fut]
                    try:
                        entries, end = fut.result()
                        ledger.data.reached = hull([ledger.data.reached or state, end.state])
                        ends.append(end)
                    except Exception as exc:  # the task itself could not run (KilledWorker, lost cluster, ...)
                        entries = [(n, FrameEntry(status="failed", error=one_line(exc))) for n in chunk]
                    fut.release()
                    for n, entry in entries:
                        name = frame_name(n)
                        ledger.record(name, entry)
                        computed[name] = entry
                        if entry.status == "done":
                            status.done += 1
                            failed.pop(name, None)
                        else:
                            status.failed += 1
                            failed[name] = entry.error or ""
                    ledger.save()
                    if progress:
                        progress(status)
                return [*ends, ChunkEnd(ledger.data.reached or state, [])]  # and what earlier runs reached

            ledger.data.search = settle(run_round, start, decision.planned)
            ledger.save()
            compute_seconds = clock() - t_compute
    elif not ledger.path.exists():
        ledger.save()
    final = [e for e in computed.values() if e.report is not None and ledger.data.search is not None
             and e.start == ledger.data.search.state]  # fmt: skip
    seconds = clock() - t0
    done = [e for e in computed.values() if e.status == "done"]  # each frame set once, by its last pass
    workers: dict[str, int] = {}
    for e in done:
        workers[e.worker] = workers.get(e.worker, 0) + 1
    return ProcessSummary(
        take=str(options.take),
        out=str(options.out),
        ledger=str(ledger.path),
        frames=sum(len(c) for c in work.chunks),
        chunks=len(chunks_seen),
        computed=len(done),
        failed=len(failed),
        skipped_done=len(skipped),
        failed_frames=failed,
        frames_by_worker=workers,
        range=ledger.data.range,
        search=ledger.data.search,
        widenings=sum(len(e.report.widenings) for e in final if e.report is not None),
        bound_hit_pixels=sum(e.report.bound_hit_pixels for e in final if e.report is not None),
        seconds=seconds,
        compute_seconds=compute_seconds,
        frames_per_second=len(done) / compute_seconds if compute_seconds > 0 and done else 0.0,
        recomputed=status.done + status.failed - len(computed),
        chunks_recomputed=chunks_run - len(chunks_seen),
    )
