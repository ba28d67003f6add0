"""What saturates during a load benchmark's window: CPU by process group, PostgreSQL's waits.

A thread samples, every quarter second, the CPU ticks (/proc/<pid>/stat) of the server's
process tree (the `tomstudy serve` process and its workers) and of every PostgreSQL process
pg_stat_activity lists, and, with PostgreSQL, what its active client backends wait on
(wait_event_type / wait_event: `Lock`/`advisory` is the session start's lock, `IO`/`WALSync`
an fsync of the WAL). Beside them: this process's own CPU (the load generator shares the
machine), the whole machine's (/proc/stat: what other programs used) and pg_stat_wal's
writes and fsyncs (their time only with track_wal_io_timing, which `time_wal_io` turns on).
`verdict` says in one line which of these is the limit.
"""

import math
import os
import subprocess
import sys
import threading
import time
from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path

TICKS_PER_S = os.sysconf("SC_CLK_TCK")
BUSY_SHARE = 0.85  # a group using this share of what it could use is CPU bound
WAL_WAITS = ("IO:WALSync", "IO:WALWrite", "IO:WALInitSync", "LWLock:WALWrite")
ACTIVITY = ("SELECT pid, datname = current_database() AS ours, state, backend_type, "
            "wait_event_type, wait_event FROM pg_stat_activity WHERE pid <> pg_backend_pid()")
WAL = "SELECT wal_write, wal_sync, wal_write_time, wal_sync_time FROM pg_stat_wal"


@dataclass
class Usage:
    """One window's CPU (percent of one core, by group) and PostgreSQL's waits."""

    seconds: float
    cores: int
    cpu: dict[str, float]  # workers, postgres, client, machine
    waits: Counter = field(default_factory=Counter)  # "type:event" over active backends
    active: int = 0  # active client backends seen, summed over samples
    wal: dict[str, float] | None = None  # pg_stat_wal's changes over the window


def cpu_ticks(pid: int) -> int | None:
    """utime + stime of `pid` in clock ticks, None once it is gone."""
    try:
        fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    except (FileNotFoundError, ProcessLookupError, IndexError):
        return None
    return int(fields[11]) + int(fields[12])


def process_tree(root: int) -> set[int]:
    """`root` and every process below it."""
    children: dict[int, list[int]] = {}
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            ppid = int(stat.read_text().rsplit(")", 1)[1].split()[1])
        except (FileNotFoundError, ProcessLookupError, IndexError):
            continue
        children.setdefault(ppid, []).append(int(stat.parent.name))
    tree, todo = set(), [root]
    while todo:
        pid = todo.pop()
        tree.add(pid)
        todo += children.get(pid, [])
    return tree


def machine_ticks() -> tuple[int, int]:
    """(busy, total) clock ticks of every core since boot (/proc/stat)."""
    values = [int(v) for v in Path("/proc/stat").read_text().split("\n", 1)[0].split()[1:]]
    idle = values[3] + values[4]  # idle, iowait
    return sum(values) - idle, sum(values)


def time_wal_io(url: str) -> None:
    """Turn on track_wal_io_timing on a cluster this benchmark owns (pg_stat_wal's times)."""
    from sqlalchemy import create_engine, text

    engine = create_engine(url, isolation_level="AUTOCOMMIT")
    with engine.connect() as conn:
        conn.execute(text("ALTER SYSTEM SET track_wal_io_timing = on"))
        conn.execute(text("SELECT pg_reload_conf()"))
    engine.dispose()


class Sampler:
    """Samples a server's process tree and, given its URL, its PostgreSQL database."""

    def __init__(self, server_pid: int, postgres_url: str | None = None,
                 every_s: float = 0.25) -> None:
        self.server_pid, self.every_s = server_pid, every_s
        self.engine = None
        if postgres_url:
            from sqlalchemy import create_engine

            self.engine = create_engine(postgres_url, isolation_level="AUTOCOMMIT")

    def start(self) -> None:
        """Begin a window."""
        self.ticks: dict[tuple[str, int], list[int]] = {}
        self.waits: Counter = Counter()
        self.active = 0
        self.halt = threading.Event()
        self.began = (time.perf_counter(), time.process_time(), machine_ticks())
        self.wal_before = self.wal()
        self.thread = threading.Thread(target=self.loop, daemon=True)
        self.thread.start()

    def stop(self) -> Usage:
        """End the window; what it used."""
        self.halt.set()
        self.thread.join()
        (wall0, client0, (busy0, total0)), (busy1, total1) = self.began, machine_ticks()
        seconds = time.perf_counter() - wall0
        cores = os.cpu_count() or 1
        cpu = {group: 0.0 for group in ("workers", "postgres")}
        for (group, _), (first, last) in self.ticks.items():
            cpu[group] += (last - first) / TICKS_PER_S / seconds * 100
        cpu["client"] = (time.process_time() - client0) / seconds * 100
        cpu["machine"] = (busy1 - busy0) / max(total1 - total0, 1) * cores * 100
        wal = self.wal()
        change = ({k: wal[k] - self.wal_before[k] for k in wal} if wal else None)
        return Usage(seconds, cores, cpu, self.waits, self.active, change)

    def close(self) -> None:
        """Release the database connections."""
        if self.engine is not None:
            self.engine.dispose()

    def loop(self) -> None:
        while not self.halt.wait(self.every_s):
            self.sample()

    def sample(self) -> None:
        """One look at every process's CPU and every backend's wait."""
        groups = {"workers": process_tree(self.server_pid), "postgres": self.backends()}
        for group, pids in groups.items():
            for pid in pids:
                ticks = cpu_ticks(pid)
                if ticks is not None:
                    self.ticks.setdefault((group, pid), [ticks, ticks])[1] = ticks

    def backends(self) -> set[int]:
        """PostgreSQL's processes (counting the waits of the active client backends)."""
        if self.engine is None:
            return set()
        from sqlalchemy import text

        with self.engine.connect() as conn:
            rows = conn.execute(text(ACTIVITY)).all()
        for row in rows:
            if row.ours and row.state == "active" and row.backend_type == "client backend":
                self.active += 1
                self.waits[f"{row.wait_event_type}:{row.wait_event}"
                           if row.wait_event_type else "running"] += 1
        return {row.pid for row in rows}

    def wal(self) -> dict[str, float] | None:
        """pg_stat_wal's cumulative writes, fsyncs and their times (ms), None without
        PostgreSQL."""
        if self.engine is None:
            return None
        from sqlalchemy import text

        with self.engine.connect() as conn:
            return dict(conn.execute(text(WAL)).mappings().one())


def verdict(usage: Usage, workers: int) -> str:
    """One line: which CPU is busy, and what PostgreSQL's active backends wait on."""
    cpu, capacity = usage.cpu, usage.cores * 100
    ours = cpu["workers"] + cpu["postgres"] + cpu["client"]
    split = (f"workers {cpu['workers']:.0f}%, postgres {cpu['postgres']:.0f}%, client "
             f"{cpu['client']:.0f}%, others {max(cpu['machine'] - ours, 0):.0f}% of {capacity}%")
    if cpu["machine"] >= BUSY_SHARE * capacity:
        line = f"{split}: CPU bound (the machine's cores are busy)"
    elif cpu["workers"] >= BUSY_SHARE * min(workers, usage.cores) * 100:
        line = f"{split}: the {workers} worker(s) CPU bound"
    else:
        line = f"{split}: CPU not saturated"
    return line + waits_line(usage)


def waits_line(usage: Usage) -> str:
    """PostgreSQL's share of active-backend samples per wait, and its WAL fsyncs."""
    if usage.wal is None:
        return "; SQLite: lock and fsync waits are not sampled"
    if not usage.active:
        return "; no PostgreSQL backend was active when sampled"
    share = {k: n / usage.active * 100 for k, n in usage.waits.items()}
    wal_share = sum(share.get(k, 0) for k in WAL_WAITS)
    locks = sum(v for k, v in share.items() if k.startswith("Lock:") and k != "Lock:advisory")
    top = ", ".join(f"{k} {v:.0f}%" for k, v in sorted(share.items(), key=lambda kv: -kv[1])[:3])
    syncs = usage.wal["wal_sync"] / usage.seconds
    busy = usage.wal["wal_sync_time"] / 1000 / usage.seconds * 100
    return (f"; of {usage.active} active-backend samples {share.get('Lock:advisory', 0):.0f}% "
            f"wait on the advisory lock, {locks:.0f}% on other locks, {wal_share:.0f}% on WAL "
            f"writes/fsyncs (top: {top}); {syncs:.0f} WAL fsyncs/s, fsync busy {busy:.0f}% of "
            "the window")


class Profile:
    """py-spy sampling one worker process for a window (--nonblocking: the worker is not
    paused); `top` names where its time went."""

    def __init__(self, pid: int, seconds: float, out: Path) -> None:
        py_spy = Path(sys.executable).parent / "py-spy"
        if not py_spy.is_file():
            raise FileNotFoundError(f"{py_spy}: --profile needs py-spy (requirements/dev.txt)")
        self.out = out
        self.proc = subprocess.Popen(
            [str(py_spy), "record", "--pid", str(pid), "--duration", str(math.ceil(seconds)),
             "--rate", "50", "--nonblocking", "--format", "raw", "--output", str(out)],
            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)

    def top(self, count: int = 4) -> str:
        """The functions with most samples on top of the stack, and the project's functions
        deepest in it (with what they call): shares of the worker's busy samples."""
        self.proc.wait(timeout=120)
        leaf, inside, total = Counter(), Counter(), 0
        for line in self.out.read_text().splitlines() if self.out.is_file() else []:
            stack, _, samples = line.rpartition(" ")
            frames = [frame_name(f) for f in stack.split(";")]
            total += int(samples)
            leaf[frames[-1]] += int(samples)
            ours = [f for f in frames if f.split(" ")[-1].startswith("app/")]
            inside[ours[-1] if ours else "(outside the project's code)"] += int(samples)
        if not total:
            return "no samples (py-spy could not attach)"
        return (f"on top of the stack {shares(leaf, total, count)}; the project's deepest "
                f"function {shares(inside, total, count)}")


def shares(counter: Counter, total: int, count: int) -> str:
    """The `count` commonest entries with their share of `total`."""
    return ", ".join(f"{name} {n / total:.0%}" for name, n in counter.most_common(count))


def frame_name(frame: str) -> str:
    """py-spy's `func (path:line)` as `func path`, a project path from its app/ on."""
    func, _, where = frame.partition(" (")
    path = where.rsplit(":", 1)[0]
    return f"{func or '?'} {path[path.rfind('/app/') + 1:] if '/app/' in path else path}"


def busiest_worker(server_pid: int) -> int:
    """The server process below `server_pid` (itself with one worker) that has used most CPU."""
    tree = process_tree(server_pid)
    return max(tree, key=lambda pid: (cpu_ticks(pid) or 0, pid != server_pid))
