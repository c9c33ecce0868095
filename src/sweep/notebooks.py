"""The figure notebooks run against the cube: all in this one process (`run_notebooks`, the rule
`notebook`), or one in a Jupyter kernel (`run_notebook`). Each notebook reads the cube named by
SWEEP_CUBE and saves its figure (PNG) to SWEEP_FIGURE; the executed notebook is written with its
outputs.
"""
from __future__ import annotations

import os
import shutil
import tempfile
from collections.abc import Mapping, Sequence
from pathlib import Path


# A notebook cell that runs longer than this is stuck: the figure notebooks reduce the cube
# with dask and plot a handful of panels, which takes seconds even for 10^6 scenes.
NOTEBOOK_CELL_TIMEOUT_S = 600


# The longest folder for the kernel's Unix sockets (a socket path, folder + "/kernel-NNNNN", has
# at most 107 bytes on Linux).
UNIX_SOCKET_DIR_MAX = 90


def _write_notebook(nb, path: str | Path) -> None:
    """Write an executed notebook atomically."""
    import nbformat

    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.parent / f".{path.name}.tmp-{os.getpid()}"
    nbformat.write(nb, str(tmp))
    os.replace(tmp, path)


def run_notebook(notebook: str | Path, cube: str | Path, figure: str | Path,
                 executed: str | Path | None = None, log_path: str | Path | None = None) -> Path:
    """Execute a figure notebook with nbclient; it reads the cube and saves `figure` (PNG).

    The paths reach the kernel as the environment variables SWEEP_CUBE and SWEEP_FIGURE
    (absolute). The executed notebook, with its outputs, is written to `executed`.
    """
    import nbclient
    import nbformat
    from traitlets.config import Config

    figure = Path(figure).resolve()
    figure.parent.mkdir(parents=True, exist_ok=True)
    figure.unlink(missing_ok=True)
    env_keys = {"SWEEP_CUBE": str(Path(cube).resolve()), "SWEEP_FIGURE": str(figure),
                "MPLBACKEND": "Agg"}
    saved = {k: os.environ.get(k) for k in env_keys}
    os.environ.update(env_keys)  # the kernel inherits this process's environment
    # The kernel talks to this process over Unix sockets in a folder of its own, not over TCP: a
    # TCP port is picked free and then bound by the kernel, and two notebooks starting at once
    # (snakemake -j2) could pick the same one ("Address already in use", the kernel dies and the
    # figure job fails).
    # a socket's path has at most ~107 bytes; a cluster's TMPDIR can be deep ("sweep-kernel-" and
    # mkdtemp's suffix add 22)
    deep = len(tempfile.gettempdir()) + 22 > UNIX_SOCKET_DIR_MAX
    sockets = tempfile.mkdtemp(prefix="sweep-kernel-", dir="/tmp" if deep else None)
    config = Config()
    config.KernelManager.transport = "ipc"
    config.KernelManager.ip = os.path.join(sockets, "kernel")
    try:
        nb = nbformat.read(str(notebook), as_version=4)
        # log level ERROR: no start-up warnings from the kernel
        client = nbclient.NotebookClient(nb, timeout=NOTEBOOK_CELL_TIMEOUT_S, kernel_name="python3",
                                         resources={"metadata": {"path": str(Path.cwd())}},
                                         extra_arguments=["--log-level=ERROR"], config=config)
        client.execute()
    finally:
        shutil.rmtree(sockets, ignore_errors=True)
        for k, v in saved.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v
    if executed is not None:
        _write_notebook(nb, executed)
    if not figure.exists():
        raise RuntimeError(f"notebook {notebook} ran but did not write {figure}")
    if log_path is not None:
        Path(log_path).parent.mkdir(parents=True, exist_ok=True)
        Path(log_path).write_text(f"executed {notebook} -> {figure}\n", encoding="utf-8")
    return figure


def _cell_outputs(nbformat, stdout: str, stderr: str, result, figures: list[bytes]) -> list:
    import base64

    outs = []
    if stdout:
        outs.append(nbformat.v4.new_output("stream", name="stdout", text=stdout))
    if stderr:
        outs.append(nbformat.v4.new_output("stream", name="stderr", text=stderr))
    if result is not None:
        outs.append(nbformat.v4.new_output("execute_result", data={"text/plain": repr(result)}))
    for png in figures:
        outs.append(nbformat.v4.new_output("display_data", data={"image/png": base64.b64encode(png).decode("ascii"),
                                                                  "text/plain": "<Figure>"}))
    return outs


def _mtime(path: str) -> int | None:
    try:
        return os.stat(path).st_mtime_ns if path else None
    except OSError:
        return None


def execute_in_process(notebook: str | Path, env: Mapping[str, str]):
    """Execute a notebook's code cells in this process (a fresh namespace, `env` set in
    os.environ meanwhile) and return it with its outputs as Jupyter would store them: each cell's
    stdout and stderr, the value of a last expression, and the figures left open at its end (PNG,
    as the inline backend shows them). A cell that raises gets its error output and the run stops
    with RuntimeError naming the notebook and the cell. No kernel is started: what the notebooks
    import (numpy, xarray, matplotlib, the package) is imported once for all of them."""
    import ast
    import contextlib
    import io as _stdio
    import traceback

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import nbformat

    nb = nbformat.read(str(notebook), as_version=4)
    saved_figure = env.get("SWEEP_FIGURE", "")
    saved = {k: os.environ.get(k) for k in env}
    os.environ.update(env)
    namespace: dict = {"__name__": "__main__"}
    count = 0
    plt.close("all")
    try:
        for cell in nb.cells:
            if cell.cell_type != "code":
                continue
            count += 1
            out, err = _stdio.StringIO(), _stdio.StringIO()
            before = _mtime(saved_figure)
            tree = ast.parse(cell.source)
            last = tree.body.pop() if tree.body and isinstance(tree.body[-1], ast.Expr) else None
            result = None
            try:
                with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
                    exec(compile(tree, f"<{Path(notebook).name} cell {count}>", "exec"), namespace)
                    if last is not None:
                        result = eval(compile(ast.Expression(last.value), f"<{Path(notebook).name} cell {count}>",
                                              "eval"), namespace)
            except Exception as exc:
                cell.outputs = _cell_outputs(nbformat, out.getvalue(), err.getvalue(), None, []) + [
                    nbformat.v4.new_output("error", ename=type(exc).__name__, evalue=str(exc),
                                           traceback=traceback.format_exception(exc))]
                cell.execution_count = count
                raise RuntimeError(f"notebook {notebook}, cell {count} raised {type(exc).__name__}: {exc}") from exc
            pngs = []
            saved_now = _mtime(saved_figure) != before
            for num in plt.get_fignums():
                if saved_now:   # the figure the cell saved: shown as saved, not drawn a second time
                    pngs.append(Path(saved_figure).read_bytes())
                    saved_now = False
                    continue
                buf = _stdio.BytesIO()
                plt.figure(num).savefig(buf, format="png", dpi=72)
                pngs.append(buf.getvalue())
            plt.close("all")
            cell.outputs = _cell_outputs(nbformat, out.getvalue(), err.getvalue(), result, pngs)
            cell.execution_count = count
    finally:
        for k, v in saved.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v
    return nb


def run_notebooks(notebooks: Sequence[str | Path], cube: str | Path, figures: Sequence[str | Path],
                  executed: Sequence[str | Path], log_path: str | Path | None = None) -> list[Path]:
    """Execute figure notebooks against the cube, all in this one process (execute_in_process):
    each saves its figure (`figures`, PNG) and is written with its outputs to `executed`
    (atomically). What the rule `notebook` runs; notebooks.run_notebook runs one in a Jupyter kernel."""
    import time

    lines = []
    done = []
    for notebook, figure, ex in zip(notebooks, figures, executed):
        t0 = time.perf_counter()
        figure = Path(figure).resolve()
        figure.parent.mkdir(parents=True, exist_ok=True)
        figure.unlink(missing_ok=True)
        env = {"SWEEP_CUBE": str(Path(cube).resolve()), "SWEEP_FIGURE": str(figure), "MPLBACKEND": "Agg"}
        nb = execute_in_process(notebook, env)
        _write_notebook(nb, ex)
        if not figure.exists():
            raise RuntimeError(f"notebook {notebook} ran but did not write {figure}")
        lines.append(f"executed {notebook} -> {figure} in {time.perf_counter() - t0:.2f} s")
        done.append(figure)
    if log_path is not None:
        Path(log_path).parent.mkdir(parents=True, exist_ok=True)
        Path(log_path).write_text("\n".join(lines) + "\n", encoding="utf-8")
    return done
