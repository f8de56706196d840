"""`twin compare --backend ray` on a real two-node Ray cluster on this machine, against `--backend local` on the
same config: the same rows (apart from wall-clock timings), and the wall time of each.

    python bench/bench_ray_cluster.py [--config compare-smoke] [--keep-venv DIR] [--workers 2]

What it builds, as the README's "Running a comparison on a Ray cluster" says a user does:
* a head node (`ray start --head --num-cpus 0`) from this virtualenv: it only drives, so every run that
  needs a CPU is placed on the second node;
* a second node started from a NEW virtualenv that holds only the wheel built from this checkout (`pip wheel
  --no-deps` of a copy of it, then `pip install 'twin-*.whl[all]'`, pinned to this virtualenv's versions: Ray
  wants the same Ray and Python on every node). It starts outside the checkout with a clean PYTHONPATH and,
  where `unshare` works (root), in a mount namespace where the checkout is an empty directory, as on another
  machine: a run that reads anything of the driver's but its task fails there;
* token authentication as documented: RAY_AUTH_MODE=token on every node and the driver; the head writes the
  token to its ~/.ray/auth_token (a temporary HOME here) and the bench copies it into the second node's HOME.
Free ports and temporary directories throughout; the cluster is always stopped at the end by ending the
process groups this bench started (never a global `ray stop`, which would end every Ray on the machine).

Checks (exit 1 when one fails): the cluster has two nodes and the head no CPU; a probe task ran on the second
node and imported twin from its virtualenv (and could not see the checkout); both sweeps wrote the same run
ids, and every row is equal to its local twin apart from wall-clock fields (`bench_compare._difference`).
`--keep-venv DIR` builds the second node's virtualenv in DIR once and reuses it (reinstalling only twin).
"""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "tests"))
from bench_compare import _difference  # noqa: E402 - the same row comparison as bench_compare
from test_package import _build_wheel as build_wheel  # noqa: E402 - the wheel the packaging tests install

VENV_BIN = Path(sys.executable).parent


def free_port() -> int:
    """A TCP port nobody listens on now (bound and released; Ray binds it a moment later)."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def run(cmd: list[str], **kw: Any) -> subprocess.CompletedProcess[str]:
    r = subprocess.run(cmd, capture_output=True, text=True, check=False, **kw)
    if r.returncode != 0:
        raise SystemExit(f"failed ({r.returncode}): {' '.join(cmd)}\n{(r.stdout + r.stderr)[-3000:]}")
    return r


def clean_env(**extra: str) -> dict[str, str]:
    """This environment without what would point a process at the checkout or at another Ray."""
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "RAY_ADDRESS", "VIRTUAL_ENV")}
    env.update(extra)
    return env


# ---- the second node's virtualenv: only the wheel ---------------------------------------------------------
def worker_venv(dest: Path, tmp: Path) -> tuple[Path, float]:
    """(the python of a virtualenv in `dest` holding the wheel of this checkout and its dependencies, seconds
    spent). An existing one (`--keep-venv`) gets only the new wheel."""
    t0 = time.perf_counter()
    wheel = build_wheel(tmp)
    python = dest / "bin" / "python"
    env = clean_env()
    if python.is_file():
        run([str(python), "-m", "pip", "install", "-q", "--no-deps", "--force-reinstall", str(wheel)], cwd=tmp, env=env)
        return python, time.perf_counter() - t0
    constraints = ROOT / "constraints.txt"
    if not constraints.is_file():  # pin every dependency to this virtualenv's version (Ray: the same everywhere)
        constraints = tmp / "constraints.txt"
        frozen = run([sys.executable, "-m", "pip", "freeze", "--exclude-editable"]).stdout
        constraints.write_text("\n".join(line for line in frozen.splitlines() if not line.startswith("twin")))
    print(f"building the second node's virtualenv in {dest} (a few minutes the first time) ...", flush=True)
    run([sys.executable, "-m", "venv", "--clear", str(dest)], cwd=tmp, env=env)
    run([str(python), "-m", "pip", "install", "-q", f"{wheel}[all]", "-c", str(constraints)], cwd=tmp, env=env)
    return python, time.perf_counter() - t0


# ---- the cluster ---------------------------------------------------------------------------------------
def hide_checkout_prefix() -> list[str]:
    """A command prefix that runs its command where the checkout is an empty directory (a private mount
    namespace), or [] where that is not allowed (not root, no unshare)."""
    probe = ["unshare", "--mount", "--propagation", "private", "sh", "-c", f"mount -t tmpfs none '{ROOT}' && true"]
    try:
        ok = subprocess.run(probe, capture_output=True, check=False, timeout=30).returncode == 0
    except (OSError, subprocess.TimeoutExpired):
        ok = False
    if not ok:
        return []
    script = f'mount -t tmpfs -o size=1m none "{ROOT}" && exec "$@"'
    return ["unshare", "--mount", "--propagation", "private", "sh", "-c", script, "sh"]


class Cluster:
    """A head node (this virtualenv, 0 CPUs) and a second node (`python`'s virtualenv, `cpus` CPUs), each a
    `ray start --block` in its own process group, so ending the group ends that node and only it."""

    def __init__(self, tmp: Path, python: Path, cpus: int) -> None:
        self.tmp, self.python, self.cpus = tmp, python, cpus
        self.procs: list[subprocess.Popen[bytes]] = []
        self.port = free_port()
        self.address = f"127.0.0.1:{self.port}"
        self.head_home, self.node_home = tmp / "head-home", tmp / "node-home"
        self.hidden = False

    def env(self, home: Path) -> dict[str, str]:
        return clean_env(HOME=str(home), RAY_AUTH_MODE="token", RAY_USAGE_STATS_ENABLED="0")

    def _ports(self) -> list[str]:
        out = []
        for flag in (
            "--node-manager-port",
            "--object-manager-port",
            "--dashboard-agent-listen-port",
            "--dashboard-agent-grpc-port",
            "--metrics-export-port",
            "--runtime-env-agent-port",
        ):
            out += [flag, str(free_port())]
        return [*out, "--min-worker-port", "0", "--max-worker-port", "0"]

    def _start(self, name: str, cmd: list[str], home: Path, cwd: Path) -> None:
        log = (self.tmp / f"{name}.log").open("wb")
        p = subprocess.Popen(
            cmd, cwd=cwd, env=self.env(home), stdout=log, stderr=subprocess.STDOUT, start_new_session=True
        )
        self.procs.append(p)

    def start(self) -> None:
        for d in (self.head_home, self.node_home):
            d.mkdir()
        # the head's token: `ray start --head` with RAY_AUTH_MODE=token makes none, it wants one in ~/.ray/auth_token
        run([str(VENV_BIN / "ray"), "get-auth-token", "--generate"], env=self.env(self.head_home), cwd=self.tmp)
        head = [str(VENV_BIN / "ray"), "start", "--head", "--block", "--num-cpus", "0", "--port", str(self.port)]
        head += ["--node-ip-address", "127.0.0.1", "--include-dashboard", "false", "--disable-usage-stats"]
        head += ["--temp-dir", str(self.tmp / "ray-head"), *self._ports()]
        self._start("head", head, self.head_home, self.tmp)
        token = self.head_home / ".ray" / "auth_token"
        self._wait(lambda: self._up(1), "the head node", "head")
        # "copy the token to every node": the second node's HOME gets the head's file
        (self.node_home / ".ray").mkdir()
        shutil.copy2(token, self.node_home / ".ray" / "auth_token")
        ray = self.python.parent / "ray"
        node = [str(ray), "start", "--block", "--address", self.address, "--num-cpus", str(self.cpus)]
        node += ["--node-ip-address", "127.0.0.1", "--disable-usage-stats", *self._ports()]
        prefix = hide_checkout_prefix()
        self.hidden = bool(prefix)
        cwd = self.tmp / "node-cwd"
        cwd.mkdir()
        self._start("node", [*prefix, *node], self.node_home, cwd)
        self._wait(lambda: self._up(2), "the second node", "node")

    def _up(self, nodes: int) -> bool:
        r = subprocess.run(
            [str(VENV_BIN / "ray"), "status", "--address", self.address],
            capture_output=True,
            text=True,
            env=self.env(self.head_home),
            cwd=self.tmp,
            check=False,
            timeout=60,
        )
        if r.returncode != 0:
            return False
        active = r.stdout.split("Active:", 1)[-1].split("Pending:", 1)[0]
        return active.count("node_") >= nodes

    def _wait(self, ready: Any, what: str, log: str, timeout_s: float = 120.0) -> None:
        t_end = time.monotonic() + timeout_s
        while time.monotonic() < t_end:
            if any(p.poll() is not None for p in self.procs):
                break
            if ready():
                return
            time.sleep(1.0)
        text = (self.tmp / f"{log}.log").read_text(errors="replace")
        raise SystemExit(f"{what} did not come up; its log ends:\n{text[-3000:]}")

    def stop(self) -> None:
        """SIGTERM to each node's `ray start --block` (it stops its node's processes), then SIGKILL to the
        process group of whatever is left; the second node first, as `ray stop` would order it."""
        for p in reversed(self.procs):
            if p.poll() is None:
                p.send_signal(signal.SIGTERM)
            with contextlib.suppress(subprocess.TimeoutExpired):
                p.wait(30)
            with contextlib.suppress(ProcessLookupError):
                os.killpg(p.pid, signal.SIGKILL)
            p.wait(10)


PROBE = """
import json, os, sys, ray
CHECKOUT = sys.argv[1]
ray.init(address=os.environ["RAY_ADDRESS"], log_to_driver=False)

@ray.remote(num_cpus=1)
def where():
    import twin
    return {"node": ray.get_runtime_context().get_node_id(), "python": sys.executable, "twin": twin.__file__,
            "sees_checkout": os.path.isfile(os.path.join(CHECKOUT, "pyproject.toml"))}

nodes = [{"id": n["NodeID"], "head": n["Resources"].get("node:__internal_head__", 0) > 0,
          "cpus": n["Resources"].get("CPU", 0)} for n in ray.nodes() if n["Alive"]]
print(json.dumps({"nodes": nodes, "task": ray.get(where.remote())}))
"""


def probe(cluster: Cluster) -> dict[str, Any]:
    """Where a task that needs one CPU runs on this cluster, and what it imports twin from."""
    script = cluster.tmp / "probe.py"
    script.write_text(PROBE)
    env = dict(cluster.env(cluster.head_home), RAY_ADDRESS=cluster.address)
    r = run([sys.executable, str(script), str(ROOT)], cwd=cluster.tmp, env=env, timeout=300)
    return dict(json.loads(r.stdout.strip().splitlines()[-1]))


# ---- the two sweeps ------------------------------------------------------------------------------------
def sweep(config: str, backend: str, out: Path, env: dict[str, str], cwd: Path, workers: int) -> tuple[float, list]:
    """`twin compare CONFIG --backend B` from this virtualenv, outside the checkout; (wall s, rows)."""
    cmd = [
        str(VENV_BIN / "twin"),
        "compare",
        config,
        "--backend",
        backend,
        "--out",
        str(out),
        "--workers",
        str(workers),
    ]
    t0 = time.perf_counter()
    r = subprocess.run(cmd, cwd=cwd, env=env, capture_output=True, text=True, check=False, timeout=3600)
    wall = time.perf_counter() - t0
    if r.returncode != 0:
        raise SystemExit(f"twin compare --backend {backend} failed ({r.returncode}):\n{(r.stdout + r.stderr)[-3000:]}")
    rows = [json.loads(line) for line in (out / "results.jsonl").read_text().splitlines() if line.strip()]
    return wall, rows


def compare_rows(local_rows: list[dict[str, Any]], ray_rows: list[dict[str, Any]]) -> tuple[dict[str, str], list[str]]:
    """({run_id: first field that differs} of the rows both sweeps ran, failures): rows are matched by run id
    and compared by `bench_compare._difference` (everything but wall-clock fields, `metrics`, `status` and
    `failure` among them)."""
    failures = []
    local = {r["run_id"]: r for r in local_rows}
    remote = {r["run_id"]: r for r in ray_rows}
    if set(local) != set(remote):
        only_local, only_ray = len(set(local) - set(remote)), len(set(remote) - set(local))
        failures.append(f"run ids differ: {only_local} only local, {only_ray} only on ray")
    differ: dict[str, str] = {}
    for rid in sorted(local.keys() & remote.keys()):
        why = _difference(local[rid], remote[rid])
        missing = [k for k in ("metrics", "status", "failure") if k not in local[rid] or k not in remote[rid]]
        if why is not None or missing:
            differ[rid] = why or f"{missing[0]}: missing"
    if differ:
        failures.append(f"{len(differ)} rows differ apart from wall-clock fields")
    return differ, failures


def bench(args: argparse.Namespace, tmp: Path) -> int:
    config = str(Path(args.config).resolve()) if Path(args.config).is_file() else args.config
    failures: list[str] = []
    venv = Path(args.keep_venv).resolve() if args.keep_venv else tmp / "node-venv"
    (tmp / "wheel").mkdir()
    python, venv_s = worker_venv(venv, tmp / "wheel")
    cluster = Cluster(tmp, python, args.workers)
    try:
        t0 = time.perf_counter()
        cluster.start()
        start_s = time.perf_counter() - t0
        where = probe(cluster)
        ray_env = dict(cluster.env(cluster.head_home), RAY_ADDRESS=cluster.address)
        ray_wall, ray_rows = sweep(config, "ray", tmp / "out-ray", ray_env, tmp, args.workers)
    finally:
        cluster.stop()
    local_wall, local_rows = sweep(config, "local", tmp / "out-local", clean_env(), tmp, args.workers)

    nodes, task = where["nodes"], where["task"]
    heads = [n for n in nodes if n["head"]]
    if len(nodes) != 2 or len(heads) != 1 or heads[0]["cpus"] != 0:
        failures.append(f"expected a head with 0 CPUs and one more node, got {nodes}")
    if heads and task["node"] == heads[0]["id"]:
        failures.append("the probe task ran on the head node")
    if not Path(task["twin"]).is_relative_to(venv):
        failures.append(f"the second node imported twin from {task['twin']}, not from {venv}")
    if cluster.hidden and task["sees_checkout"]:
        failures.append("the second node can read the checkout")
    differ, row_failures = compare_rows(local_rows, ray_rows)
    failures += row_failures
    errors = {
        b: sum(r.get("status") == "error" for r in rows) for b, rows in (("local", local_rows), ("ray", ray_rows))
    }

    print(f"twin compare {args.config}: --backend local vs --backend ray on a two-node cluster ({args.workers} CPUs)")
    hidden = "hidden from it" if cluster.hidden else "NOT hidden from it (no unshare)"
    print(f"  second node: {venv} (only the wheel; the checkout {hidden})")
    head_id = heads[0]["id"][:12] if heads else "?"
    print(f"  probe task ran on node {task['node'][:12]} (head {head_id}, 0 CPUs), twin from {task['twin']}")
    print(f"  virtualenv {venv_s:.0f} s, cluster start {start_s:.1f} s")
    print(f"  {'backend':8s} {'runs':>5s} {'errors':>7s} {'wall s':>8s}")
    for name, rows, wall in (("local", local_rows, local_wall), ("ray", ray_rows, ray_wall)):
        print(f"  {name:8s} {len(rows):5d} {errors[name]:7d} {wall:8.1f}")
    shared = len({r["run_id"] for r in local_rows} & {r["run_id"] for r in ray_rows})
    print(f"  rows equal apart from wall-clock fields: {shared - len(differ)} of {len(local_rows)}")
    for rid, why in list(differ.items())[:10]:
        print(f"    {rid}: {why[:160]}")
    for f in failures:
        print(f"FAIL: {f}")
    print("OK" if not failures else "FAILED")
    return 1 if failures else 0


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--config", default="compare-smoke", help="comparison config (default: compare-smoke)")
    ap.add_argument("--keep-venv", default=None, metavar="DIR", help="the second node's virtualenv: built once, reused")
    ap.add_argument("--workers", type=int, default=2, help="CPUs of the second node and local workers (default 2)")
    args = ap.parse_args()
    tmp = Path(tempfile.mkdtemp(prefix="bench-ray-cluster-"))
    try:
        return bench(args, tmp)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


if __name__ == "__main__":
    raise SystemExit(main())
