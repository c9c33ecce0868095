"""The front door's command line (`python3 run.py sweep [snakemake args...]`) as Snakemake reads it:
Snakemake's own parse, the arguments added for a run (`-j2` unless set, `--rerun-incomplete`), the
options whose values are paths (made absolute against the user's directory, shown as given), and
the config files of a run in Snakemake's order.
"""
from __future__ import annotations

import contextlib
import io as _stdio
import os
from collections.abc import Mapping
from pathlib import Path

from . import configfiles


# the project root: the Snakefile, config/, workflow/ (src/sweep/snakemake_args.py -> ../..)
PROJECT_ROOT = Path(__file__).resolve().parents[2]
DEFAULT_JOBS = "2"


# options whose values are paths (taken relative to the user's directory): how many values
PATH_OPTIONS = {"--configfile": "+", "--configfiles": "+", "--snakefile": 1, "-s": 1, "--directory": 1,
                "-d": 1, "--profile": 1}


# options after which nothing is validated: Snakemake answers without reading the workflow
HELP_OPTIONS = {"-h", "--help", "--version", "-v", "--help-snakemake"}


# Snakemake options after which its own console output is what the user wants
RAW_OPTIONS = {
    "-n", "--dry-run", "--dryrun", "--unlock", "--lint", "-l", "--list", "--list-rules",
    "--list-target-rules", "--lt", "-h", "--help", "--version", "-v", "-S", "--summary",
    "-D", "--detailed-summary", "--dag", "--rulegraph", "--filegraph", "--d3dag",
    "--cleanup-metadata", "--cm", "--list-changes", "--lc", "--list-input-changes", "--li",
    "--list-params-changes", "--lp", "--list-code-changes", "--list-untracked", "--lu",
    "--delete-all-output", "--delete-temp-output", "--archive", "--report", "-t", "--touch",
    "--cleanup-shadow", "--print-compilation", "--generate-unit-tests", "--containerize",
    "--verbose", "--debug", "--debug-dag", "--export-cwl", "--conda-create-envs-only",
}


def parsed_args(argv: list[str], cwd: Path = PROJECT_ROOT):
    """Snakemake's own parse of `argv` (profile defaults applied, a relative profile path found
    from `cwd`, where Snakemake runs), or None if it rejects it."""
    from snakemake.cli import parse_args

    with contextlib.redirect_stderr(_stdio.StringIO()), contextlib.redirect_stdout(_stdio.StringIO()), \
            contextlib.chdir(cwd):
        try:
            return parse_args(list(argv))[1]
        except SystemExit:
            return None


def snakemake_argv(argv: list[str], progress: bool) -> list[str]:
    """The Snakemake arguments for `run.py sweep argv`: `-j2` unless `argv` or its profile set
    jobs/cores; `--rerun-incomplete` for a run (so an interrupted run resumes as it was started)."""
    args = parsed_args(argv)
    extra = []
    if args is not None and args.jobs is None and args.cores is None:
        extra += ["-j", DEFAULT_JOBS]
    if progress and "--rerun-incomplete" not in argv and "--ri" not in argv:
        extra.append("--rerun-incomplete")
    return extra + list(argv)


def is_raw(argv: list[str]) -> bool:
    return any(a.split("=", 1)[0] in RAW_OPTIONS for a in argv)


def absolute_paths(argv: list[str], cwd: Path) -> tuple[list[str], dict[str, str]]:
    """`argv` with the values of PATH_OPTIONS made absolute against `cwd` (a `--profile` only if
    it names a folder or file there; else it is a profile name or a path in the project), and
    {absolute path: the path as the user wrote it}, to name files as given."""
    out: list[str] = []
    given: dict[str, str] = {}

    def absolute(opt: str, value: str) -> str:
        p = Path(value).expanduser()
        if opt == "--profile" and not (cwd / p).exists():
            return value
        full = str(p if p.is_absolute() else cwd / p)
        given.setdefault(full, value)
        return full

    i = 0
    while i < len(argv):
        a = argv[i]
        opt, eq, value = a.partition("=")
        if eq and opt.startswith("--") and opt in PATH_OPTIONS:
            out.append(f"{opt}={absolute(opt, value)}")
        elif a in PATH_OPTIONS:
            out.append(a)
            n = 0
            while i + 1 < len(argv) and not argv[i + 1].startswith("-") and (PATH_OPTIONS[a] == "+" or n < 1):
                i += 1
                n += 1
                out.append(absolute(a, argv[i]))
        else:
            out.append(a)
        i += 1
    return out, given


def shown_path(path: Path, cwd: Path | None = None) -> str:
    """A path as a message shows it: relative to the user's directory if inside it."""
    cwd = cwd or Path.cwd()
    path = Path(path)
    return str(path.relative_to(cwd)) if path.is_absolute() and path.is_relative_to(cwd) else str(path)


def command_prefix() -> str:
    """How the user started the front door, for the resume command: `python3 run.py` as typed
    (run.py passes it in SWEEP_COMMAND), e.g. `python3 ../sweep/run.py` from another directory."""
    return os.environ.get("SWEEP_COMMAND", "python3 run.py")


def config_files(args, given: Mapping[str, str], cwd: Path) -> tuple[Path, list[tuple[Path, str]], dict | None]:
    """(Snakemake's working directory, the config files in Snakemake's order as (path, as the
    user named it), the --config overrides) of a run parsed as `args` (absolute paths)."""
    from snakemake.cli import parse_config

    workdir = Path(args.directory) if args.directory else PROJECT_ROOT
    files: list[tuple[Path, str]] = []
    if not getattr(args, "replace_workflow_config", False):
        default = workdir / configfiles.DEFAULT_CONFIG
        files.append((default, shown_path(default, cwd)))
    for f in args.configfile or []:
        f = Path(f)
        if all(f != p for p, _ in files):
            files.append((f, given.get(str(f), shown_path(f, cwd))))
    overrides = parse_config(args.config) if args.config else None
    return workdir, files, overrides
