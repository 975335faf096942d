"""``matremap doctor``: what this installation can do, and what to install for the rest.

It lists Python's and matremap's versions; the core dependencies; each renderer backend with its version
(the embedded one; Mitsuba 3 with its variants and whether ``llvm_ad_rgb`` renders, which needs a libLLVM
>= 17 such as Debian's ``libllvm19``; Blender Cycles through the bpy worker venv, with Blender's version);
the optional pieces (MaterialX and its standard data libraries, usd-core, scikit-learn, Dask, pyarrow); the
cache folder (``$MATREMAP_CACHE`` or the default) and its size; and, for each piece that is missing, the
command that installs it. Nothing is rendered but the few pixels that tell whether the LLVM variant works.

Imports that can hang or crash the interpreter (compiled renderers, USD, bpy) run in child processes,
all at once, each bounded by a timeout: a piece that times out or crashes is reported as such and the
others still are. The exit status is 0 when the core works (optional pieces may be missing) and 4
(:data:`matremap.errors.EXIT_RENDERER`, the environment) when it does not.
"""

from __future__ import annotations

import argparse
import glob
import importlib.util
import json
import os
import platform
import re
import subprocess
import sys
import time
from collections.abc import Mapping
from concurrent.futures import ThreadPoolExecutor
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

from matremap import __version__
from matremap.cli.common import Subparsers, add_command, add_json_option
from matremap.errors import EXIT_RENDERER

DOCTOR_EXAMPLES = """examples:
  matremap doctor
  matremap doctor --json | jq '.pieces[] | select(.status != "ok")'
  MATREMAP_CACHE=/scratch/matremap matremap doctor      (where the cache would be, and its size)"""

#: the last line each probe prints: ``RESULT {json}``
_MARK = "RESULT "

_PREAMBLE = f"""
import json, sys
def out(**kw):
    print({_MARK!r} + json.dumps(kw), flush=True)
"""

#: probe name -> the code a child process runs (the main venv's Python, except ``bpy``)
PROBES: dict[str, str] = {
    "core": """
import importlib, importlib.metadata as md
found, failed = {}, {}
for dist, module in (("numpy", "numpy"), ("scipy", "scipy"), ("OpenImageIO", "OpenImageIO"),
                     ("threadpoolctl", "threadpoolctl"), ("tqdm", "tqdm"), ("matplotlib", "matplotlib"),
                     ("scikit-image", "skimage"), ("colour-science", "colour"), ("defusedxml", "defusedxml")):
    try:
        importlib.import_module(module)
        found[dist] = md.version(dist) if dist != "OpenImageIO" else importlib.import_module(module).__version__
    except Exception as e:
        failed[dist] = f"{type(e).__name__}: {e}"
out(found=found, failed=failed)
""",
    "mitsuba3": """
import mitsuba as mi, drjit as dr
out(version=mi.__version__, drjit=dr.__version__, variants=list(mi.variants()))
""",
    "materialx": """
import MaterialX as mx
doc = mx.createDocument()
folders = mx.getDefaultDataLibraryFolders()
search = mx.getDefaultDataSearchPath()
mx.loadLibraries(folders, search, doc)
where = [str(p) for p in search.asString().split(mx.PATH_LIST_SEPARATOR) if p]
out(version=mx.getVersionString(), nodedefs=len(doc.getNodeDefs()), search=where, folders=list(folders))
""",
    "usd": """
import importlib.metadata as md
from pxr import Usd
try:
    out(version=md.version("usd-core"))
except md.PackageNotFoundError:  # a USD build of its own: (0, 25, 11) is 25.11
    out(version=".".join(str(v) for v in Usd.GetVersion()).removeprefix("0."))
""",
    "scikit-learn": """
import sklearn
out(version=sklearn.__version__)
""",
    "dask": """
import dask, distributed
out(version=dask.__version__, distributed=distributed.__version__)
""",
    "pyarrow": """
import pyarrow
out(version=pyarrow.__version__)
""",
    "bpy": """
import bpy
out(version=bpy.app.version_string)
""",
}

#: optional piece -> (the extra of matremap's install that brings it, what it is for)
EXTRAS = {
    "mitsuba3": ("mitsuba", "the mitsuba3 renderer (--target-renderer mitsuba3, mitsuba3:* models)"),
    "materialx": ("materialx", "reading and writing MaterialX documents (.mtlx)"),
    "usd": ("usd", "reading and writing USD files (.usda, .usdc, .usdz)"),
    "scikit-learn": ("svr", "learn --method svr"),
    "dask": ("dask", "--scheduler and --dask-local (sweeps and batches on Dask)"),
    "pyarrow": ("parquet", "export to .parquet"),
}

LLVM_HINT = "apt-get install -y libllvm19   (Debian/Ubuntu; Mitsuba finds it by itself; or set DRJIT_LIBLLVM_PATH)"


@dataclass
class Piece:
    """One thing the installation has or lacks."""

    name: str
    group: str  # core | renderer | format | extra
    status: str  # ok | missing | broken
    version: str = ""
    detail: str = ""
    install: str = ""  # the command that installs (or fixes) it, when it is not ok
    used_for: str = ""


@dataclass
class Probe:
    """What a child process said: its RESULT, or why there is none."""

    result: dict[str, Any] | None
    failure: str = ""  # "timed out after N s", "crashed (signal N)", the last line of its error
    seconds: float = 0.0


def run_probes(probes: Mapping[str, tuple[str, str]], timeout: float) -> dict[str, Probe]:
    """Run every probe (name -> (python executable, code)) in its own child process at once; each is
    given ``timeout`` seconds from the start, then killed."""
    started = time.monotonic()
    procs: dict[str, subprocess.Popen[str] | str] = {}
    for name, (python, code) in probes.items():
        try:
            procs[name] = subprocess.Popen(
                [python, "-c", _PREAMBLE + code],
                stdout=subprocess.PIPE,
                stderr=subprocess.PIPE,
                stdin=subprocess.DEVNULL,
                text=True,
            )
        except OSError as e:
            procs[name] = f"cannot start {python}: {e.strerror or e}"
    results: dict[str, Probe] = {}
    for name, proc in procs.items():
        if isinstance(proc, str):
            results[name] = Probe(None, proc)
            continue
        left = max(0.1, timeout - (time.monotonic() - started))
        try:
            out, err = proc.communicate(timeout=left)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.communicate()
            results[name] = Probe(None, f"timed out after {timeout:g} s", time.monotonic() - started)
            continue
        results[name] = _read_probe(proc.returncode, out, err, time.monotonic() - started)
    return results


def _read_probe(code: int, out: str, err: str, seconds: float) -> Probe:
    lines = [ln for ln in out.splitlines() if ln.startswith(_MARK)]
    if code == 0 and lines:
        return Probe(json.loads(lines[-1][len(_MARK) :]), seconds=seconds)
    if code < 0:
        return Probe(None, f"crashed (signal {-code})", seconds)
    tail = [ln.strip() for ln in err.strip().splitlines() if ln.strip()]
    return Probe(None, tail[-1] if tail else f"exited with status {code}", seconds)


def install_command(extra: str) -> str:
    """The exact command that installs an extra's packages into this Python (from matremap's metadata)."""
    import importlib.metadata as md

    try:
        requires = md.requires("matremap") or []
    except md.PackageNotFoundError:
        requires = []
    wanted = [r.split(";")[0].strip() for r in requires if re.search(rf"""extra\s*==\s*["']{extra}["']""", r)]
    packages = " ".join(f"'{w}'" for w in wanted) or f"'matremap[{extra}]'"
    return f"{sys.executable} -m pip install {packages}"


def llvm_libraries() -> list[str]:
    """The libLLVM shared libraries on the system's usual paths (what Dr.Jit's LLVM backend may load)."""
    paths = glob.glob("/usr/lib/*/libLLVM*.so*") + glob.glob("/usr/lib/llvm-*/lib/libLLVM*.so*")
    return sorted({p for p in paths if re.search(r"libLLVM[-.]?\d*(\.\d+)*\.so", os.path.basename(p))})


def _llvm_majors(paths: list[str]) -> list[int]:
    majors = set()
    for p in paths:
        digits = re.findall(r"\d+", os.path.basename(p))
        if digits:
            majors.add(int(digits[0]))
    return sorted(majors)


def mitsuba_piece(probe: Probe, llvm: bool) -> Piece:
    """Mitsuba 3: version, variants, and whether ``llvm_ad_rgb`` renders (``llvm``: a 4 x 4 test render in a
    child process, :func:`matremap.renderers.mitsuba3.plugins.llvm_renders`)."""
    if probe.result is None:
        return _missing("mitsuba3", "renderer", probe, "mitsuba")
    r = probe.result
    variants = r.get("variants", [])
    detail = f"drjit {r.get('drjit')}; variants {', '.join(v for v in variants if v.endswith('_rgb'))}"
    majors = _llvm_majors(llvm_libraries())
    found = f"libLLVM {', '.join(map(str, majors))} found" if majors else "no libLLVM found"
    if "llvm_ad_rgb" not in variants:
        return Piece("mitsuba3", "renderer", "ok", r.get("version", ""), detail + "; this build has no llvm_ad_rgb")
    if llvm:
        return Piece("mitsuba3", "renderer", "ok", r.get("version", ""), f"{detail}; llvm_ad_rgb renders ({found})")
    return Piece(
        "mitsuba3",
        "renderer",
        "ok",
        r.get("version", ""),
        f"{detail}; llvm_ad_rgb does not render ({found}; it needs >= 17), so scalar_rgb draws (slower)",
        install=LLVM_HINT,
        used_for="the faster llvm_ad_rgb variant (optional)",
    )


def cycles_piece(probe: Probe | None, python: str | None, hint: str) -> Piece:
    if python is None:
        return Piece("cycles", "renderer", "missing", detail="no bpy worker venv found", install=hint)
    if probe is None or probe.result is None:
        why = probe.failure if probe else "not probed"
        return Piece("cycles", "renderer", "broken", detail=f"{python} cannot import bpy: {why}", install=hint)
    return Piece("cycles", "renderer", "ok", probe.result["version"], f"Blender {probe.result['version']} in {python}")


def materialx_piece(probe: Probe) -> Piece:
    if probe.result is None:
        return _missing("materialx", "format", probe, "materialx")
    r = probe.result
    libs = [str(Path(s) / f) for s in r.get("search", []) for f in r.get("folders", []) if (Path(s) / f).is_dir()]
    if not r.get("nodedefs"):
        return Piece(
            "materialx",
            "format",
            "broken",
            r.get("version", ""),
            "the standard data libraries were not found (no node definitions loaded); documents cannot be validated",
            install=install_command("materialx").replace(" install ", " install --force-reinstall "),
        )
    where = libs[0] if libs else "the package"
    return Piece(
        "materialx", "format", "ok", r["version"], f"data libraries {where} ({r['nodedefs']} node definitions)"
    )


def _missing(name: str, group: str, probe: Probe, extra: str) -> Piece:
    crashed = "crashed" in probe.failure or "timed out" in probe.failure
    no_module = "No module named" in probe.failure or "ModuleNotFoundError" in probe.failure
    status = "missing" if no_module else "broken"
    detail = probe.failure if not no_module else "not installed"
    if crashed:
        detail = f"importing it {probe.failure}"
    return Piece(name, group, status, detail=detail, install=install_command(extra), used_for=EXTRAS[name][1])


def cache_piece() -> dict[str, Any]:
    """Where the cache is (``$MATREMAP_CACHE`` or the default), whether it exists, and its size."""
    from matremap.core.diskcache import CACHE_ENV, cache_dir

    folder = cache_dir()
    source = next((f"${name}" for name in CACHE_ENV if os.environ.get(name)), "default")
    size, files, transforms = 0, 0, 0
    if folder.is_dir():
        for root, _, names in os.walk(folder):
            for n in names:
                try:
                    size += os.lstat(os.path.join(root, n)).st_size
                except OSError:
                    continue
                files += 1
                transforms += root.startswith(str(folder / "transforms")) and n.endswith(".json")
    return {
        "path": str(folder),
        "from": source,
        "exists": folder.is_dir(),
        "bytes": size,
        "files": files,
        "transforms": transforms,
    }


def diagnose(timeout: float = 30.0) -> dict[str, Any]:
    """Everything ``matremap doctor`` reports, as a JSON-ready dict (``core_ok`` decides the exit status)."""
    from matremap.renderers.cycles.client import INSTALL_HINT as BPY_HINT
    from matremap.renderers.cycles.client import find_python

    try:
        bpy_python: str | None = find_python()
    except Exception:  # noqa: BLE001 - no venv found: reported as missing
        bpy_python = None
    probes = {name: (sys.executable, code) for name, code in PROBES.items() if name != "bpy"}
    if bpy_python is not None:
        probes["bpy"] = (bpy_python, PROBES["bpy"])
    t0 = time.monotonic()
    with ThreadPoolExecutor(1) as pool:  # the LLVM variant's test render runs beside the imports
        llvm = pool.submit(_llvm_renders) if importlib.util.find_spec("mitsuba") else None
        got = run_probes(probes, timeout)
        llvm_ok = llvm is not None and llvm.result()
    core = got["core"]
    pieces = [Piece("python", "core", "ok", platform.python_version(), sys.executable)]
    if core.result is None:
        pieces.append(Piece("core dependencies", "core", "broken", detail=core.failure, install=_core_install()))
    else:
        for dist, version in core.result["found"].items():
            pieces.append(Piece(dist, "core", "ok", version))
        for dist, why in core.result["failed"].items():
            pieces.append(Piece(dist, "core", "broken", detail=why, install=_core_install(dist)))
    pieces.append(Piece("embedded", "renderer", "ok", __version__, "numpy; built in, deterministic"))
    pieces.append(mitsuba_piece(got["mitsuba3"], llvm_ok))
    pieces.append(cycles_piece(got.get("bpy"), bpy_python, BPY_HINT))
    pieces.append(materialx_piece(got["materialx"]))
    for name, group in (("usd", "format"), ("scikit-learn", "extra"), ("dask", "extra"), ("pyarrow", "extra")):
        probe = got[name]
        if probe.result is None:
            pieces.append(_missing(name, group, probe, EXTRAS[name][0]))
        else:
            extra = f"distributed {probe.result['distributed']}" if "distributed" in probe.result else ""
            pieces.append(Piece(name, group, "ok", probe.result["version"], extra))
    core_ok = all(p.status == "ok" for p in pieces if p.group == "core")
    return {
        "matremap": __version__,
        "python": platform.python_version(),
        "executable": sys.executable,
        "platform": f"{platform.system()} {platform.machine()}",
        "core_ok": core_ok,
        "pieces": [asdict(p) for p in pieces],
        "cache": cache_piece(),
        "seconds": round(time.monotonic() - t0, 2),
    }


def _llvm_renders() -> bool:
    from matremap.renderers.mitsuba3.plugins import llvm_renders

    return llvm_renders()


def _core_install(dist: str | None = None) -> str:
    what = f"'{dist}'" if dist else "-e ."
    return f"{sys.executable} -m pip install {what}   (a core dependency of matremap)"


def _size(n: int) -> str:
    for unit in ("B", "KB", "MB", "GB"):
        if n < 1024 or unit == "GB":
            return f"{n:.0f} {unit}" if unit == "B" else f"{n:.1f} {unit}"
        n /= 1024  # type: ignore[assignment]
    return f"{n} B"  # pragma: no cover


def report_lines(doc: Mapping[str, Any]) -> list[str]:
    """The text report of :func:`diagnose`'s dict."""
    lines = [f"matremap {doc['matremap']} on Python {doc['python']} ({doc['executable']}), {doc['platform']}"]
    titles = {"core": "core", "renderer": "renderers", "format": "material file formats", "extra": "extras"}
    for group, title in titles.items():
        lines.append(title)
        for p in doc["pieces"]:
            if p["group"] == group:
                text = " ".join(x for x in (p["version"], p["detail"] and f"({p['detail']})") if x)
                lines.append(f"  {p['status']:<8} {p['name']:<18} {text}".rstrip())
    c = doc["cache"]
    where = "set by " + c["from"] if c["from"] != "default" else "the default; set MATREMAP_CACHE to move it"
    size = (
        f"{_size(c['bytes'])} in {c['files']} files, {c['transforms']} learned transforms" if c["exists"] else "empty"
    )
    lines += ["cache", f"  {c['path']} ({where}): {size if c['exists'] else 'not created yet'}"]
    todo = [p for p in doc["pieces"] if p["install"]]
    if todo:
        lines.append("to install")
        for p in todo:
            lines.append(f"  {p['name']}{' (' + p['used_for'] + ')' if p['used_for'] else ''}:")
            lines.append(f"    {p['install']}")
    missing = sum(p["status"] != "ok" for p in doc["pieces"])
    verdict = "the core works" if doc["core_ok"] else "the core does NOT work (see above)"
    lines.append(f"{verdict}; {missing} optional piece(s) missing or broken; checked in {doc['seconds']:.1f} s")
    return lines


def add_doctor(subparsers: Subparsers) -> None:
    """The ``doctor`` command."""
    p = add_command(
        subparsers,
        "doctor",
        "check the installation: versions, renderers, formats, the cache, and what to install",
        DOCTOR_EXAMPLES,
    )
    add_json_option(p, "the report")
    p.add_argument(
        "--timeout",
        type=float,
        default=30.0,
        metavar="SECONDS",
        help="give each check (an import in a child process) at most this long (default %(default)s)",
    )
    p.set_defaults(func=cmd_doctor)


def cmd_doctor(args: argparse.Namespace) -> int:
    """Print the report; 0 when the core works, 4 when it does not."""
    doc = diagnose(args.timeout)
    if args.json:
        print(json.dumps(doc, indent=1))
    else:
        print("\n".join(report_lines(doc)))
    return 0 if doc["core_ok"] else EXIT_RENDERER


#: command name -> the function adding its parser
PARSERS = {"doctor": add_doctor}
