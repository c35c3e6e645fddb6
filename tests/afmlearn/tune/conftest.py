"""A real PostgreSQL server on loopback for the shared-storage tests.

``postgres_url`` (session scope) finds Debian's server binaries (``/usr/lib/postgresql/*/bin``),
installs the ``postgresql`` package with apt-get if they are missing and we are root (as in CI),
creates a throw-away cluster in a temporary folder owned by a non-root user (the server refuses
to run as root: the package's ``postgres`` user), starts it on a free loopback port and yields
``postgresql://postgres@127.0.0.1:<port>/afmlearn_test``; the server is stopped and the folder
removed afterwards. The tests using it are skipped, with the reason, only where the server
cannot be installed or started.
"""

from __future__ import annotations

import glob
import os
import pwd
import shutil
import socket
import subprocess
import tempfile
from collections.abc import Iterator
from pathlib import Path

import pytest


def _pg_bin() -> Path | None:
    found = sorted(glob.glob("/usr/lib/postgresql/*/bin/initdb"),
                   key=lambda p: int(Path(p).parts[-3]) if Path(p).parts[-3].isdigit() else 0)
    return Path(found[-1]).parent if found else None


def _install() -> str | None:
    """Install Debian's postgresql; None on success, else the reason."""
    if os.geteuid() != 0:
        return "PostgreSQL is not installed and the tests do not run as root (cannot apt-get)"
    if shutil.which("apt-get") is None:
        return "PostgreSQL is not installed and apt-get is not available"
    env = {**os.environ, "DEBIAN_FRONTEND": "noninteractive"}
    for cmd in (["apt-get", "install", "-y", "-q", "--no-install-recommends", "postgresql"],
                ["apt-get", "update", "-q"],
                ["apt-get", "install", "-y", "-q", "--no-install-recommends", "postgresql"]):
        done = subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=900)
        if cmd[1] == "install" and done.returncode == 0:
            return None
    return f"apt-get install postgresql failed: {done.stderr.strip()[-300:]}"


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def _as_user(user: str | None, cmd: list[str]) -> list[str]:
    return cmd if user is None else ["runuser", "-u", user, "--", *cmd]


@pytest.fixture(scope="session")
def postgres_url() -> Iterator[str]:
    """URL of a running throw-away PostgreSQL server on 127.0.0.1 (see the module doc)."""
    bin_dir = _pg_bin()
    if bin_dir is None:
        reason = _install()
        bin_dir = _pg_bin()
        if bin_dir is None:
            pytest.skip(reason or "postgresql installed but no /usr/lib/postgresql/*/bin/initdb")
    user = None
    if os.geteuid() == 0:
        try:
            pwd.getpwnam("postgres")
        except KeyError:
            pytest.skip("running as root and there is no 'postgres' user to run the server")
        user = "postgres"
    root = Path(tempfile.mkdtemp(prefix="afmlearn-pg-"))
    data, sock = root / "data", root / "sock"
    sock.mkdir()
    if user is not None:
        entry = pwd.getpwnam(user)
        os.chmod(root, 0o755)
        for path in (root, sock):
            os.chown(path, entry.pw_uid, entry.pw_gid)
    port = _free_port()
    env = {**os.environ, "LC_ALL": "C", "LANG": "C"}

    def run(cmd: list[str]) -> subprocess.CompletedProcess[str]:
        return subprocess.run(_as_user(user, cmd), env=env, capture_output=True, text=True,
                              timeout=120, cwd=root)

    try:
        steps = [
            # UTF8: under SQL_ASCII psycopg 3 returns bytes and SQLAlchemy cannot read them
            [str(bin_dir / "initdb"), "-D", str(data), "-A", "trust", "-U", "postgres",
             "-E", "UTF8", "--no-sync"],
            [str(bin_dir / "pg_ctl"), "-D", str(data), "-w", "-t", "60", "-l",
             str(root / "server.log"), "-o",
             f"-p {port} -k {sock} -c listen_addresses=127.0.0.1 -c fsync=off", "start"],
            [str(bin_dir / "createdb"), "-h", "127.0.0.1", "-p", str(port), "-U", "postgres",
             "afmlearn_test"],
        ]
        for cmd in steps:
            done = run(cmd)
            if done.returncode != 0:
                log = (root / "server.log").read_text() if (root / "server.log").exists() else ""
                pytest.skip(f"PostgreSQL could not be started ({Path(cmd[0]).name}): "
                            f"{(done.stderr or log).strip()[-300:]}")
        yield f"postgresql://postgres@127.0.0.1:{port}/afmlearn_test"
    finally:
        if data.exists():
            run([str(bin_dir / "pg_ctl"), "-D", str(data), "-m", "immediate", "-w", "stop"])
        shutil.rmtree(root, ignore_errors=True)
