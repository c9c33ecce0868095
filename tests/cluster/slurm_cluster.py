"""A one-node SLURM cluster on localhost, started as the current user, for the live-cluster tests.

Installs nothing: it needs `munged`, `slurmctld`, `slurmd` and the client commands (`sinfo`,
`sbatch`, `squeue`, `scancel`) on PATH, i.e. Debian's `munge`, `slurmctld`, `slurmd` and
`slurm-client` packages (.ci/run installs them). Everything else lives in one directory:

    <dir>/slurm.conf     one node (this machine's cores and memory), one partition `sweeptest`
    <dir>/munge.*        a private munge daemon (own key and socket: no system munge needed)
    <dir>/state, spool   slurmctld state, slurmd spool
    <dir>/*.log          daemon logs (read them when a test fails)

Job status: there is no accounting database (AccountingStorageType=accounting_storage/none), so
`sacct` has nothing to report; the executor plugin is told to use its `squeue` status query
(`--slurm-status-command squeue`), which sees finished jobs for MinJobAge = 300 s.

`srun` inside a job: the jobstep executor plugin (snakemake-executor-plugin-slurm-jobstep 0.6.1)
starts each job of a group with `srun` in an environment stripped of every `SLURM_*` variable
but the job's identity, SLURM_CONF included, so its `srun` looks for /etc/slurm/slurm.conf (or a
configless DNS record) and fails on a cluster found only through SLURM_CONF, like this one. The
cluster therefore puts `<dir>/bin/srun` first on PATH, which sets SLURM_CONF and runs the real
srun. (A site cluster has its slurm.conf at the default path or configless; it needs no shim.)

Use from Python (tests/test_slurm.py) or by hand:

    python3 tests/cluster/slurm_cluster.py start /tmp/slurm   # prints the SLURM_CONF to export
    python3 tests/cluster/slurm_cluster.py stop /tmp/slurm
"""
from __future__ import annotations

import os
import pwd
import shutil
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

DAEMONS = ("munged", "slurmctld", "slurmd")
CLIENTS = ("sinfo", "sbatch", "squeue", "scancel", "scontrol", "srun")
PARTITION = "sweeptest"
NODE = "sweepnode"
START_TIMEOUT_S = 60


def missing_binaries() -> list[str]:
    return [b for b in DAEMONS + CLIENTS if shutil.which(b) is None
            and not Path("/usr/sbin", b).exists()]


def _exe(name: str) -> str:
    return shutil.which(name) or str(Path("/usr/sbin", name))


def slurm_version() -> str:
    return subprocess.run([_exe("slurmctld"), "-V"], capture_output=True, text=True).stdout.strip()


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _memory_mb() -> int:
    for line in Path("/proc/meminfo").read_text().splitlines():
        if line.startswith("MemTotal:"):
            return int(line.split()[1]) // 1024
    return 1024


class Cluster:
    """A running one-node cluster; `env` is the environment for client commands and Snakemake."""

    def __init__(self, root: Path):
        self.root = Path(root).resolve()
        self.conf = self.root / "slurm.conf"
        self.procs: dict[str, subprocess.Popen] = {}
        self.bin = self.root / "bin"
        self.env = dict(os.environ, SLURM_CONF=str(self.conf),
                        PATH=f"{self.bin}{os.pathsep}{os.environ.get('PATH', '')}")
        self.cpus = os.cpu_count() or 1
        # leave room for the OS; the jobs of the tests ask for a few hundred MB at most
        self.memory_mb = max(256, int(_memory_mb() * 0.8))

    # ------------------------------------------------------------------------ configuration
    def write_config(self) -> None:
        user = pwd.getpwuid(os.getuid()).pw_name
        for d in ("state", "spool", "munge"):
            (self.root / d).mkdir(parents=True, exist_ok=True)
        key = self.root / "munge" / "munge.key"
        if not key.exists():
            key.write_bytes(os.urandom(1024))
            key.chmod(0o400)
        (self.root / "munge").chmod(0o700)
        self.bin.mkdir(exist_ok=True)
        srun = self.bin / "srun"   # see the module docstring: SLURM_CONF for the jobs' srun
        srun.write_text(f"#!/bin/sh\nSLURM_CONF={self.conf} exec {shutil.which('srun') or '/usr/bin/srun'} \"$@\"\n")
        srun.chmod(0o755)
        self.conf.write_text(f"""\
# one-node test cluster written by tests/cluster/slurm_cluster.py
ClusterName=sweeptest
SlurmctldHost=localhost(127.0.0.1)
SlurmctldPort={_free_port()}
SlurmdPort={_free_port()}
SlurmUser={user}
SlurmdUser={user}
AuthType=auth/munge
CredType=cred/munge
AuthInfo=socket={self.root / 'munge' / 'munge.socket'}
StateSaveLocation={self.root / 'state'}
SlurmdSpoolDir={self.root / 'spool'}
SlurmctldPidFile={self.root / 'slurmctld.pid'}
SlurmdPidFile={self.root / 'slurmd.pid'}
SlurmctldLogFile={self.root / 'slurmctld.log'}
SlurmdLogFile={self.root / 'slurmd.log'}
SlurmctldDebug=info
SlurmdDebug=info
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
JobAcctGatherType=jobacct_gather/none
AccountingStorageType=accounting_storage/none
JobCompType=jobcomp/none
MpiDefault=none
SchedulerType=sched/backfill
SelectType=select/cons_tres
SelectTypeParameters=CR_Core
SlurmdParameters=config_overrides
ReturnToService=2
MinJobAge=300
SchedulerParameters=defer_batch=0
NodeName={NODE} NodeHostname={socket.gethostname()} NodeAddr=127.0.0.1 CPUs={self.cpus} RealMemory={self.memory_mb} State=UNKNOWN
PartitionName={PARTITION} Nodes={NODE} Default=YES MaxTime=INFINITE State=UP OverSubscribe=NO
""")

    # ------------------------------------------------------------------------ daemons
    def _start(self, name: str, args: list[str]) -> None:
        log = open(self.root / f"{name}.out", "w")
        self.procs[name] = subprocess.Popen([_exe(name), *args], env=self.env, stdout=log,
                                            stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL,
                                            start_new_session=True)

    def start(self) -> "Cluster":
        missing = missing_binaries()
        if missing:
            raise RuntimeError(f"SLURM/munge binaries not found: {', '.join(missing)} "
                               "(Debian: apt-get install munge slurmctld slurmd slurm-client)")
        self.write_config()
        m = self.root / "munge"
        self._start("munged", ["--foreground", "--force", f"--key-file={m / 'munge.key'}",
                               f"--socket={m / 'munge.socket'}", f"--pid-file={m / 'munged.pid'}",
                               f"--log-file={m / 'munged.log'}", f"--seed-file={m / 'munged.seed'}"])
        self._wait(lambda: (m / "munge.socket").exists(), "munged socket")
        self._start("slurmctld", ["-D", "-i", "-f", str(self.conf)])
        self._wait(lambda: self.run("scontrol", "ping", check=False).returncode == 0, "slurmctld")
        self._start("slurmd", ["-D", "-N", NODE, "-f", str(self.conf)])
        self._wait(lambda: self.node_state() == "idle", f"node {NODE} idle in sinfo")
        return self

    def _wait(self, ok, what: str) -> None:
        deadline = time.monotonic() + START_TIMEOUT_S
        while not ok():
            for name, p in self.procs.items():
                if p.poll() is not None:
                    raise RuntimeError(f"{name} exited ({p.returncode}) while waiting for {what}:\n"
                                       + self.logs())
            if time.monotonic() > deadline:
                raise RuntimeError(f"timed out after {START_TIMEOUT_S} s waiting for {what}:\n" + self.logs())
            time.sleep(0.2)

    def run(self, *cmd: str, check: bool = True) -> subprocess.CompletedProcess:
        return subprocess.run(list(cmd), env=self.env, capture_output=True, text=True, check=check, timeout=60)

    def node_state(self) -> str:
        p = self.run("sinfo", "-h", "-N", "-o", "%T", check=False)
        return p.stdout.strip().rstrip("*~#") if p.returncode == 0 else ""

    def logs(self, tail: int = 40) -> str:
        out = []
        for path in sorted(self.root.glob("*.log")) + sorted(self.root.glob("*.out")) + [self.root / "munge" / "munged.log"]:
            if path.exists():
                lines = path.read_text(errors="replace").splitlines()[-tail:]
                out.append(f"--- {path.name}\n" + "\n".join(lines))
        return "\n".join(out)

    def stop(self) -> None:
        if "slurmctld" in self.procs and self.procs["slurmctld"].poll() is None:
            self.run("scancel", "--full", "-u", pwd.getpwuid(os.getuid()).pw_name, check=False)
        for name in reversed(DAEMONS):
            p = self.procs.get(name)
            if p is None or p.poll() is not None:
                continue
            try:
                os.killpg(p.pid, signal.SIGTERM)
            except ProcessLookupError:
                continue
            try:
                p.wait(timeout=20)
            except subprocess.TimeoutExpired:
                os.killpg(p.pid, signal.SIGKILL)
                p.wait(timeout=10)
        # slurmstepd of a killed job may outlive slurmd briefly; nothing else is left
        self.procs.clear()


def main(argv: list[str]) -> int:
    if len(argv) != 2 or argv[0] not in {"start", "stop"}:
        print(__doc__)
        return 2
    root = Path(argv[1])
    if argv[0] == "start":
        c = Cluster(root).start()
        (root / "pids").write_text(" ".join(str(p.pid) for p in c.procs.values()))
        print(f"{slurm_version()} running; export SLURM_CONF={c.conf}")
        return 0
    for pid in reversed((root / "pids").read_text().split()):
        try:
            os.killpg(int(pid), signal.SIGTERM)
        except ProcessLookupError:
            pass
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
