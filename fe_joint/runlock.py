"""One run per results folder: the output folder's checks and its lock file.

``DIR/run.lock`` holds the host, pid and start of the run that writes ``DIR`` (JSON). It is
made atomically — written under a private name, then hard-linked to ``run.lock``, which fails if
the name exists — so a lock file is never seen half-written. A second run finds it and stops
with exit status 2 naming the holder. A lock whose process is gone (same host, pid dead, a
zombie, or the pid reused by a process that started later) is stale: it is taken over, with one
line saying so. A holder on another host cannot be checked; the message says which file to
delete if that run is gone. Only rank 0 of an MPI run calls this (:mod:`fe_joint.cli`).
"""
from __future__ import annotations

import errno
import json
import os
import socket
import time
import uuid
from dataclasses import dataclass
from pathlib import Path

from .errors import CaseError

LOCK_FILE = "run.lock"


def _proc_start(pid: int) -> int | None:
    """Start time of a process in clock ticks since boot (Linux /proc), None if unknown."""
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return None
    # the command name (field 2) is in parentheses and may hold spaces: split after it
    rest = stat[stat.rfind(")") + 2:].split()
    return int(rest[19]) if len(rest) > 19 else None   # field 22 of stat


def _zombie(pid: int) -> bool:
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return False
    return stat[stat.rfind(")") + 2:].startswith("Z")


def process_alive(pid: int, start: int | None = None) -> bool:
    """Whether process ``pid`` of this host runs (and, if ``start`` is given, is the same
    process: a pid reused by a later process does not count)."""
    if pid <= 0:
        return False
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:   # another user's process: it exists
        return True
    if _zombie(pid):
        return False
    if start is not None:
        now = _proc_start(pid)
        if now is not None and now != start:
            return False
    return True


@dataclass
class RunLock:
    """A held lock; :meth:`release` removes the file if it is still this run's."""
    path: Path
    token: str

    def release(self) -> None:
        holder = _read(self.path)
        if holder is not None and holder.get("token") == self.token:
            try:
                self.path.unlink()
            except FileNotFoundError:
                pass


def _read(path: Path) -> dict | None:
    try:
        data = json.loads(path.read_text())
    except (OSError, ValueError):
        return None
    return data if isinstance(data, dict) else None


def _describe(h: dict) -> str:
    return f"host {h.get('host')}, pid {h.get('pid')}, since {h.get('started')}"


def _create(path: Path, me: dict) -> None:
    """Create ``path`` holding ``me``, atomically; FileExistsError if it exists."""
    tmp = path.with_name(f".{path.name}.{os.getpid()}.{me['token'][:8]}")
    tmp.write_text(json.dumps(me))
    try:
        os.link(tmp, path)
    except OSError as e:
        if e.errno == errno.EEXIST:
            raise FileExistsError(str(path)) from None
        if e.errno not in (errno.EPERM, errno.ENOTSUP, errno.EOPNOTSUPP, errno.EXDEV):
            raise
        # a file system without hard links: exclusive create (a reader may then briefly see
        # an empty file, which it treats as unreadable)
        fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o644)
        with os.fdopen(fd, "w") as f:
            f.write(json.dumps(me))
    finally:
        tmp.unlink(missing_ok=True)


def prepare_out(out: Path, option: str = "--out") -> None:
    """Check that ``out`` is, or can be made, a writable folder, and make it.

    Args:
        out: the output folder.
        option: how the message names it (``--out``, or the default folder's description).
    Raises:
        CaseError: ``out`` is a file, or cannot be created or written.
    """
    where = f"{option} {str(out)!r}"
    if out.exists() and not out.is_dir():
        raise CaseError(f"{where}: is a file, not a folder")
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as e:
        raise CaseError(f"{where}: cannot create the folder ({e.strerror or e})") from None
    if not os.access(out, os.W_OK | os.X_OK):
        raise CaseError(f"{where}: the folder is not writable")


def acquire(out: Path, option: str = "--out") -> tuple[RunLock, str | None]:
    """Take the lock of ``out`` (which must exist).

    Returns:
        (the lock, a one-line note when a stale lock was taken over, else None).
    Raises:
        CaseError: another live run holds the lock (the message names it), or the lock file
            cannot be written.
    """
    path = out / LOCK_FILE
    host, pid = socket.gethostname(), os.getpid()
    me = {"host": host, "pid": pid, "start": _proc_start(pid),
          "started": time.strftime("%Y-%m-%dT%H:%M:%S"), "token": uuid.uuid4().hex}
    note = None
    for _ in range(5):
        try:
            _create(path, me)
            return RunLock(path, me["token"]), note
        except FileExistsError:
            pass
        except OSError as e:
            raise CaseError(f"{option} {str(out)!r}: cannot write the lock file "
                            f"({e.strerror or e})") from None
        holder = _read(path)
        if holder is None:
            # unreadable: wait once for a writer without hard links, then treat it as stale
            time.sleep(0.2)
            holder = _read(path)
        if holder is not None:
            same_host = holder.get("host") == host
            hpid = holder.get("pid")
            alive = (not same_host or not isinstance(hpid, int)
                     or process_alive(hpid, holder.get("start")))
            if alive:
                raise CaseError(f"{option} {str(out)!r}: in use by another run ({_describe(holder)}); "
                                f"wait for it to end, or delete {path} if that run is gone")
            note = f"taking over the lock of a run that is no longer running ({_describe(holder)})"
        else:
            note = f"replacing an unreadable lock file {path}"
        # remove the stale lock only if it is still the one judged (another run may have
        # taken it over meanwhile)
        again = _read(path)
        if (again or {}).get("token") == (holder or {}).get("token"):
            path.unlink(missing_ok=True)
    raise CaseError(f"{option} {str(out)!r}: could not take the lock {path} (another run keeps taking it)")
