"""What matremap does with hostile and malformed inputs, one row per case.

Each case builds its input in a fresh temporary folder, runs the command line in a fresh process with a
fresh cache folder, and classifies the outcome:

* ``refused``    a one-line error (exit 2) and nothing written under -o;
* ``handled``    the expected clean outcome for that case (said in its row);
* ``TRACEBACK``  Python's traceback reached the user;
* ``LEAKED``     a file from outside the asset folder was read into the output;
* ``OUTSIDE``    something was written outside -o;
* ``WRONG``      exit 0 where the input should have been refused;
* ``LEFTOVER``   temporary files remained after the run.

    python benchmarks/hostile_inputs.py            # every case
    python benchmarks/hostile_inputs.py killed     # the cases whose name has "killed" (several: any of them)
    python benchmarks/hostile_inputs.py -v         # each row with the last line the command printed
    PYTHONPATH=OTHER/src python benchmarks/hostile_inputs.py   # another checkout (older ones: --target etc.)

The interruption cases run the command once uninterrupted, then again with a signal sent when a staging
folder appears (or a file in it has bytes, "mid-write"; for a sweep, when a point is in the database),
then a third time, the same command without ``--force``: ``handled`` when the third run exits 0, leaves no
hidden file behind and writes what the uninterrupted run wrote (and, for SIGINT, the interrupted run
exited 130 with ``matremap: interrupted`` last and no traceback).

Run it on two checkouts to compare (the issue's "probe, before, after" table).
"""

from __future__ import annotations

import functools
import importlib.util
import json
import os
import re
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
CORPUS = ROOT / "tests" / "data" / "corpus"
SECRET = b"SECRET-IMAGE-BYTES"


def png(path: Path, rgb: np.ndarray) -> None:
    import OpenImageIO as oiio

    path.parent.mkdir(parents=True, exist_ok=True)
    out = oiio.ImageOutput.create(str(path))
    if not out.open(str(path), oiio.ImageSpec(rgb.shape[1], rgb.shape[0], 3, "uint8")):
        raise OSError(f"cannot write {path}")
    out.write_image(np.round(np.clip(rgb, 0, 1) * 255).astype(np.uint8))
    out.close()


#: the module that runs the command line (``matremap.cli`` in checkouts older than ``python -m matremap``)
MODULE = "matremap" if importlib.util.find_spec("matremap.__main__") else "matremap.cli"


@functools.cache
def help_text(command: str) -> str:
    return subprocess.run([sys.executable, "-m", MODULE, command, "--help"], capture_output=True, text=True).stdout


def spelled(args: list[str]) -> list[str]:
    """``args`` in the spelling of the matremap measured: an older checkout (the "before" column) said
    ``--target`` for ``sweep`` and ``fit`` and ``--lights`` for ``remap``'s environment lights."""
    renames = {"--to": "--target", "--env-lights": "--lights"}
    text = help_text(args[0])

    def has(option: str) -> bool:
        return re.search(re.escape(option) + r"(?![\w-])", text) is not None

    return [renames[a] if a in renames and not has(a) and has(renames[a]) else a for a in args]


#: the last line the latest command printed on stderr (shown with -v: why a case was refused)
LAST: list[str] = [""]


def cli(args: list[str], cwd: Path, timeout: float = 300) -> subprocess.CompletedProcess[str]:
    env = {**os.environ, "MATREMAP_CACHE_DIR": str(cwd / "cache"), "MATREMAP_CACHE": str(cwd / "cache")}
    p = subprocess.run(
        [sys.executable, "-m", MODULE, *spelled(args)],
        cwd=cwd,
        env=env,
        capture_output=True,
        text=True,
        timeout=timeout,
    )
    LAST[0] = (p.stderr.strip().splitlines() or [""])[-1].replace(str(cwd), "T")
    return p


def classify(p: subprocess.CompletedProcess[str], out: Path, expect: str = "refused") -> str:
    if "Traceback (most recent call last)" in p.stderr:
        return "TRACEBACK"
    leaked = any(SECRET in f.read_bytes() for f in out.rglob("*") if f.is_file()) if out.exists() else False
    if leaked:
        return "LEAKED"
    if expect == "refused":
        if p.returncode == 0:
            return "WRONG"
        if p.returncode == 2 and not out.exists():
            return "refused"
        return f"exit {p.returncode}" + (" (partial output)" if out.exists() else "")
    return "handled" if p.returncode == int(expect) else f"exit {p.returncode}"


def textured_gltf(folder: Path, uri: str) -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    y, x = np.mgrid[0:8, 0:8] / 7.0
    png(folder / "base.png", np.stack([0.5 + 0.4 * x, 0.2 + 0 * y, 0.1 + 0 * x], -1))
    pbr = {"baseColorTexture": {"index": 0}, "metallicFactor": 0.0, "roughnessFactor": 0.5}
    doc = {
        "asset": {"version": "2.0"},
        "images": [{"uri": uri}],
        "textures": [{"source": 0}],
        "materials": [{"name": "m", "pbrMetallicRoughness": pbr}],
    }
    (folder / "m.gltf").write_text(json.dumps(doc))
    return folder / "m.gltf"


def gradient() -> np.ndarray:
    """An 8 x 8 RGB texture that varies (a texture of one value is written back as a constant)."""
    y, x = np.mgrid[0:8, 0:8] / 7.0
    return np.stack([0.5 + 0.4 * x, 0.2 + 0.3 * y, 0.1 + 0 * x], -1)


def secret_png(path: Path) -> Path:
    y, x = np.mgrid[0:8, 0:8] / 7.0
    png(path, np.stack([x, y, 0 * x], -1))
    with path.open("ab") as f:
        f.write(SECRET)  # trailing bytes after IEND: readers ignore them, a byte copy keeps them
    return path


# -- the cases: (name, finding, function(tmp) -> outcome) ---------------------------------------------


def gltf_absolute_uri(tmp: Path) -> str:
    secret = secret_png(tmp / "elsewhere" / "secret.png")
    src = textured_gltf(tmp / "asset", str(secret))
    return classify(cli(["remap", str(src), "--to", "gltf:metal-rough", "-o", "out"], tmp), tmp / "out")


def gltf_parent_uri(tmp: Path) -> str:
    secret_png(tmp / "secret.png")
    src = textured_gltf(tmp / "asset", "../secret.png")
    return classify(cli(["remap", str(src), "--to", "gltf:metal-rough", "-o", "out"], tmp), tmp / "out")


def gltf_symlink_out(tmp: Path) -> str:
    secret_png(tmp / "secret.png")
    src = textured_gltf(tmp / "asset", "link.png")
    (tmp / "asset" / "link.png").symlink_to(tmp / "secret.png")
    return classify(cli(["remap", str(src), "--to", "gltf:metal-rough", "-o", "out"], tmp), tmp / "out")


def mitsuba_bitmap_outside(tmp: Path) -> str:
    secret = secret_png(tmp / "secret.png")
    (tmp / "asset").mkdir()
    (tmp / "asset" / "s.xml").write_text(
        '<scene version="3.0.0"><bsdf type="diffuse" id="d"><texture type="bitmap" name="reflectance">'
        f'<string name="filename" value="{secret}"/></texture></bsdf></scene>'
    )
    return classify(cli(["remap", "asset/s.xml", "--to", "mitsuba06:diffuse", "-o", "out"], tmp), tmp / "out")


def materialx_file_outside(tmp: Path) -> str:
    secret_png(tmp / "secret.png")
    (tmp / "asset").mkdir()
    (tmp / "asset" / "m.mtlx").write_text(
        '<?xml version="1.0"?>\n<materialx version="1.39">\n'
        '  <image name="tex" type="color3"><input name="file" type="filename" value="../secret.png"/></image>\n'
        '  <standard_surface name="s" type="surfaceshader"><input name="base_color" type="color3" nodename="tex"/>'
        "</standard_surface>\n"
        '  <surfacematerial name="mat" type="material"><input name="surfaceshader" type="surfaceshader" nodename="s"/>'
        "</surfacematerial>\n</materialx>\n"
    )
    return classify(cli(["remap", "asset/m.mtlx", "--to", "gltf:metal-rough", "-o", "out"], tmp), tmp / "out")


def write_outside(tmp: Path) -> str:
    src = textured_gltf(tmp / "asset", "base.png")
    p = cli(["remap", str(src), "--to", "gltf:metal-rough", "-o", "out", "--write", "../../escaped.gltf"], tmp)
    if any(tmp.parent.glob("escaped.gltf")) or (tmp / "escaped.gltf").exists():
        return "OUTSIDE"
    return classify(p, tmp / "out")


def data_uri_bad_base64(tmp: Path) -> str:
    src = textured_gltf(tmp / "asset", "data:image/png;base64,@@@not-base64@@@")
    return classify(cli(["remap", str(src), "--to", "mitsuba06:ward", "-o", "out"], tmp), tmp / "out")


def glb_negative_length(tmp: Path) -> str:
    body = json.dumps({"asset": {"version": "2.0"}, "materials": [{"name": "m"}]}).encode()
    body += b" " * (-len(body) % 4)
    header = b"glTF" + (2).to_bytes(4, "little") + (12 + 8 + len(body)).to_bytes(4, "little")
    chunk = (2**32 - 8).to_bytes(4, "little") + b"JSON" + body  # a length that wraps negative
    (tmp / "m.glb").write_bytes(header + chunk)
    return classify(cli(["remap", "m.glb", "--to", "mitsuba06:ward", "-o", "out"], tmp), tmp / "out")


def gltf_deep_json(tmp: Path) -> str:
    (tmp / "m.gltf").write_text('{"asset": {"version": "2.0"}, "extras": ' + "[" * 100_000 + "]" * 100_000 + "}")
    return classify(cli(["remap", "m.gltf", "--to", "mitsuba06:ward", "-o", "out"], tmp), tmp / "out")


def mitsuba_billion_laughs(tmp: Path) -> str:
    ents = '<!ENTITY a0 "ha">' + "".join(f'<!ENTITY a{i} "{("&a" + str(i - 1) + ";") * 10}">' for i in range(1, 10))
    (tmp / "s.xml").write_text(
        f'<?xml version="1.0"?><!DOCTYPE scene [{ents}]><scene version="3.0.0">'
        '<bsdf type="diffuse" id="d"><string name="x" value="&a9;"/></bsdf></scene>'
    )
    return classify(cli(["remap", "s.xml", "--to", "mitsuba06:diffuse", "-o", "out"], tmp, timeout=120), tmp / "out")


def mitsuba_external_entity(tmp: Path) -> str:
    (tmp / "secret.txt").write_text("0.5, 0.5, 0.5")
    (tmp / "s.xml").write_text(
        f'<?xml version="1.0"?><!DOCTYPE scene [<!ENTITY x SYSTEM "file://{tmp / "secret.txt"}">]>'
        '<scene version="3.0.0"><bsdf type="diffuse" id="d"><rgb name="reflectance" value="&x;"/></bsdf></scene>'
    )
    return classify(cli(["remap", "s.xml", "--to", "mitsuba06:diffuse", "-o", "out"], tmp), tmp / "out")


# -- second round: expansion bounds, clean lines instead of exit 70, messages ------------------------------


def refused_with(p: subprocess.CompletedProcess[str], out: Path, says: str = "", expect: str = "refused") -> str:
    """:func:`classify`, then the line itself: one line on stderr after any progress, at most 700
    characters, no hidden temporary name, and saying ``says``."""
    outcome = classify(p, out, expect)
    if outcome not in ("refused", "handled"):
        return outcome
    line = (p.stderr.strip().splitlines() or [""])[-1]
    if len(line) > 700:
        return f"{outcome}, but a {len(line):,}-character line"
    if ".matremap-" in line:
        return f"{outcome}, but the line names a hidden temporary folder"
    if says and says not in line:
        return f"{outcome}, but the line does not say {says!r}"
    return outcome


def cli_patched(setup: str, args: list[str], cwd: Path) -> subprocess.CompletedProcess[str]:
    """The command line in a fresh process after ``setup`` (Python) ran in it: a fault injected where no
    real one can be made here (a full disk, a folder the system refuses to root)."""
    env = {**os.environ, "MATREMAP_CACHE_DIR": str(cwd / "cache"), "MATREMAP_CACHE": str(cwd / "cache")}
    code = f"{setup}\nimport sys\nfrom matremap.cli import main\nsys.exit(main({args!r}))\n"
    p = subprocess.run([sys.executable, "-c", code], cwd=cwd, env=env, capture_output=True, text=True, timeout=300)
    LAST[0] = (p.stderr.strip().splitlines() or [""])[-1].replace(str(cwd), "T")
    return p


def mtlx_chain(length: int, value: str = "0.0001, 0.0001, 0.0001") -> str:
    """A MaterialX document whose base colour is a chain of ``length`` nodes: a constant, then adds."""
    nodes = ['<constant name="n0" type="color3"><input name="value" type="color3" value="0.2, 0.3, 0.4"/></constant>']
    nodes += [
        f'<add name="n{i}" type="color3"><input name="in1" type="color3" nodename="n{i - 1}"/>'
        f'<input name="in2" type="color3" value="{value}"/></add>'
        for i in range(1, length)
    ]
    return (
        '<?xml version="1.0"?>\n<materialx version="1.39">' + "".join(nodes) + '<standard_surface name="s" '
        f'type="surfaceshader"><input name="base_color" type="color3" nodename="n{length - 1}"/></standard_surface>'
        '<surfacematerial name="mat" type="material"><input name="surfaceshader" type="surfaceshader" nodename="s"/>'
        "</surfacematerial></materialx>\n"
    )


def remap_mtlx(tmp: Path, data: bytes | str, expect: str = "refused", says: str = "", extra: tuple = ()) -> str:
    (tmp / "m.mtlx").write_bytes(data.encode() if isinstance(data, str) else data)
    p = cli(["remap", "m.mtlx", "--to", "gltf:metal-rough", "-o", "out", *extra], tmp)
    return refused_with(p, tmp / "out", says, expect)


def mitsuba_default_bomb(tmp: Path) -> str:
    defaults = '<default name="d0" value="xxxxxxxx"/>' + "".join(
        f'<default name="d{i}" value="$d{i - 1}$d{i - 1}"/>' for i in range(1, 30)
    )
    (tmp / "s.xml").write_text(
        f'<scene version="3.0.0">{defaults}<bsdf type="diffuse" id="x"><rgb name="reflectance" value="$d29"/>'
        "</bsdf></scene>"
    )
    p = cli(["remap", "s.xml", "--to", "mitsuba06:diffuse", "-o", "out"], tmp, timeout=200)
    return refused_with(p, tmp / "out", "characters")


def mitsuba_include_fan_out(tmp: Path) -> str:
    for level in range(7):
        inner = "".join(f'<include filename="f{level + 1}.xml"/>' for _ in range(8))
        (tmp / f"f{level}.xml").write_text(f'<scene version="3.0.0">{inner}</scene>')
    (tmp / "f7.xml").write_text('<scene version="3.0.0"><default name="z" value="1"/></scene>')
    (tmp / "s.xml").write_text('<scene version="3.0.0"><include filename="f0.xml"/><bsdf type="diffuse"/></scene>')
    p = cli(["remap", "s.xml", "--to", "mitsuba06:diffuse", "-o", "out"], tmp, timeout=200)
    return refused_with(p, tmp / "out", "<include>")


def mtlx_chain_200(tmp: Path) -> str:
    return remap_mtlx(tmp, mtlx_chain(200), expect="0")


def mtlx_chain_5000(tmp: Path) -> str:
    return remap_mtlx(tmp, mtlx_chain(5000), says="deeper than")


def mtlx_utf8_bom(tmp: Path) -> str:
    return remap_mtlx(tmp, b"\xef\xbb\xbf" + mtlx_chain(2).encode(), expect="0")


def mtlx_utf16(tmp: Path) -> str:
    return remap_mtlx(tmp, mtlx_chain(2).replace("?>", ' encoding="UTF-16"?>', 1).encode("utf-16"), expect="0")


def mtlx_huge_value(tmp: Path) -> str:
    return remap_mtlx(tmp, mtlx_chain(2, "9" * 1_000_000 + "x"), says="characters cut")


def mtlx_write_subfolder(tmp: Path) -> str:
    """Refused before any work: the refusal is the only line (no fit ran first)."""
    (tmp / "m.mtlx").write_text(mtlx_chain(2))
    p = cli(["remap", "m.mtlx", "--to", "gltf:metal-rough", "-o", "out", "--write", "a/b/c.gltf"], tmp)
    outcome = refused_with(p, tmp / "out", "--write c.gltf")
    return outcome if len(p.stderr.strip().splitlines()) <= 1 else f"{outcome}, but only after the work"


def fifo_texture(tmp: Path) -> str:
    os.mkfifo(tmp / "tex.png")
    doc = mtlx_chain(2).replace(
        '<constant name="n0" type="color3"><input name="value" type="color3" value="0.2, 0.3, 0.4"/></constant>',
        '<image name="n0" type="color3"><input name="file" type="filename" value="tex.png"/></image>',
    )
    return remap_mtlx(tmp, doc, says="FIFO")


def non_utf8_folder(tmp: Path) -> str:
    textured_gltf(tmp / "asset", "base.png")
    folder = os.fsencode(tmp) + b"/a\xff"
    os.rename(tmp / "asset", folder)
    p = cli(["remap", os.fsdecode(b"a\xff/m.gltf"), "--to", "mitsuba06:ward", "-o", "out"], tmp)
    return refused_with(p, tmp / "out", "UTF-8")


def non_utf8_output(tmp: Path) -> str:
    (tmp / "s.xml").write_text('<scene version="3.0.0"><bsdf type="diffuse"/></scene>')
    out = os.fsdecode(b"out\xfe")
    p = cli(["remap", "s.xml", "--to", "mitsuba06:diffuse", "-o", out], tmp)
    return refused_with(p, tmp / out, "UTF-8")


#: a render whose image write finds the disk full (after writing part of the file)
FULL_DISK = """
import errno, os
from pathlib import Path
import matremap.core.imageio as imageio
def full(path, data):
    Path(path).write_bytes(b"half")
    raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
imageio._oiio_write = full
"""


def disk_full(tmp: Path) -> str:
    (tmp / "out").mkdir()
    p = cli_patched(FULL_DISK, ["render", "mitsuba06:diffuse,reflectance=0.5", "--size", "16", "-o", "out/p.png"], tmp)
    outcome = refused_with(p, tmp / "nothing", "is full", expect="4")
    return outcome if not any((tmp / "out").iterdir()) else "LEFTOVER"


#: a sweep database that SQLite finds full after a few pages
FULL_DATABASE = """
from matremap.sweep import store
connect = store.SweepStore._connect
def small(p):
    conn = connect(p)
    conn.execute(f"PRAGMA max_page_count={conn.execute('PRAGMA page_count').fetchone()[0] + 8}")
    return conn
store.SweepStore._connect = staticmethod(small)
"""


def sqlite_full(tmp: Path) -> str:
    args = ["sweep", "--source", "mitsuba06:ward,variant=ward,diffuseReflectance=0", "--to", "mitsuba06:pbr"]
    args += ["--fix", "distribution=as", "--size", "48", "--no-progress", "--workers", "1", "--db", "s.sqlite"]
    args += ["--grid", "alpha=0.05:0.8:4,specularReflectance=0.02:0.2:3"]
    return refused_with(cli_patched(FULL_DATABASE, args, tmp), tmp / "nothing", "database or disk is full", "4")


#: the system refusing to create a file in the folder "ro" (what a read-only folder does to anyone but root)
READ_ONLY = """
import errno, os, tempfile
from pathlib import Path
mkstemp, mkdtemp = tempfile.mkstemp, tempfile.mkdtemp
def refused(make):
    def call(suffix=None, prefix=None, dir=None, *rest):
        if dir is not None and Path(dir).resolve() == Path("ro").resolve():
            name = os.path.join(dir, f"{prefix}abcdefgh{suffix or ''}")
            raise PermissionError(errno.EACCES, "Permission denied", name)
        return make(suffix, prefix, dir, *rest)
    return call
tempfile.mkstemp, tempfile.mkdtemp = refused(mkstemp), refused(mkdtemp)
"""


def read_only_out_parent(tmp: Path) -> str:
    (tmp / "ro").mkdir()
    (tmp / "s.xml").write_text('<scene version="3.0.0"><bsdf type="diffuse"/></scene>')
    p = cli_patched(READ_ONLY, ["remap", "s.xml", "--to", "mitsuba3:diffuse", "-o", "ro/out"], tmp)
    return refused_with(p, tmp / "ro" / "out", "cannot write")


def transform_with_nan(tmp: Path) -> str:
    doc = json.loads((ROOT / "src" / "matremap" / "regress" / "transforms" / "ward-as.json").read_text())
    doc["mappings"]["roughness"]["coef"] = [float("nan")] * len(doc["mappings"]["roughness"]["coef"])
    (tmp / "t.json").write_text(json.dumps(doc))  # json writes NaN, which Python's reader accepts
    p = cli(["convert", str(bronze_balanced(tmp)), "--transform", "t.json", "-o", "out"], tmp)
    return classify(p, tmp / "out")


def inline_material_long(tmp: Path) -> str:
    m = {"model": "mitsuba06:ward", "params": {"alpha": 0.2, "specularReflectance": 0.05}, "notes": "x" * 300}
    p = cli(["fit", "--source", json.dumps(m), "--to", "mitsuba06:pbr"], tmp)
    if "Traceback" in p.stderr:
        return "TRACEBACK"
    return "handled" if p.returncode in (0, 2) and "File name too long" not in p.stderr else f"exit {p.returncode}"


def sweep_db_text_numbers(tmp: Path) -> str:
    import sqlite3

    src = json.dumps({"model": "mitsuba06:ward", "params": {"alpha": 0.2, "specularReflectance": 0.05}})
    p = cli(["sweep", "--source", src, "--to", "mitsuba06:pbr", "--grid", "alpha=0.1:0.3:3", "--db", "s.sqlite"], tmp)
    if p.returncode != 0:
        return f"setup failed: {p.stderr.strip()[-80:]}"
    con = sqlite3.connect(tmp / "s.sqlite")
    tables = [r[0] for r in con.execute("select name from sqlite_master where type='table'")]
    for t in tables:
        cols = [r[1] for r in con.execute(f"pragma table_info({t})")]
        for c in cols:
            try:
                con.execute(f"update {t} set {c} = 'garbage' where rowid = 1")
            except sqlite3.Error:
                pass
    con.commit()
    con.close()
    return classify(cli(["learn", "s.sqlite", "-o", "t.json"], tmp), tmp / "t.json")


def rgb_base_metal_uniform_rough(tmp: Path) -> str:
    shutil.copytree(CORPUS / "gltf-BoxTextured", tmp / "asset")
    p = cli(["remap", "asset/BoxTextured.gltf", "--to", "mitsuba06:ward", "-o", "out"], tmp)
    if "Traceback" in p.stderr:
        return "TRACEBACK"
    return "handled" if p.returncode in (0, 3) else f"exit {p.returncode}: {p.stderr.strip().splitlines()[-1][:60]}"


# -- more of the probe: every finding's other cases --------------------------------------------------


def same_line_either_way(tmp: Path) -> str:
    """The refusal of an outside reference says the same whether the named file exists (finding 1)."""
    lines = []
    for exists in (True, False):
        case = tmp / ("exists" if exists else "missing")
        if exists:
            secret_png(case / "secret.png")
        src = textured_gltf(case / "asset", "../secret.png")
        p = cli(["remap", str(src), "--to", "gltf:metal-rough", "-o", "out"], case)
        lines.append(p.stderr.strip().replace(str(case), "T"))
    if lines[0] != lines[1]:
        return "DIFFERS (" + " / ".join(ln.splitlines()[-1][:40] for ln in lines) + ")"
    return "refused" if "outside" in lines[0] else "same line, not a refusal"


def gltf_buffer_outside(tmp: Path) -> str:
    """A glTF whose image is a buffer view of ../secret.bin (the secret bytes inside a PNG's trailer)."""
    secret = secret_png(tmp / "secret.png").rename(tmp / "secret.bin")
    src = textured_gltf(tmp / "asset", "unused.png")
    doc = json.loads(src.read_text())
    size = secret.stat().st_size
    doc["buffers"] = [{"uri": "../secret.bin", "byteLength": size}]
    doc["bufferViews"] = [{"buffer": 0, "byteLength": size}]
    doc["images"] = [{"bufferView": 0, "mimeType": "image/png"}]
    src.write_text(json.dumps(doc))
    return classify(
        cli(["remap", str(src), "--to", "gltf:metal-rough", "-o", "out", "--write", "m.glb"], tmp), tmp / "out"
    )


def gltf_copy_names_outside(tmp: Path) -> str:
    """One material remapped and written as a copy of the source, whose other material's image is outside."""
    secret_png(tmp / "secret.png")
    src = textured_gltf(tmp / "asset", "base.png")
    doc = json.loads(src.read_text())
    doc["images"].append({"uri": "../secret.png"})
    doc["textures"].append({"source": 1})
    doc["materials"].append({"name": "other", "pbrMetallicRoughness": {"baseColorTexture": {"index": 1}}})
    src.write_text(json.dumps(doc))
    args = ["remap", str(src), "--material", "m", "--to", "gltf:metal-rough", "-o", "out", "--write", "m.gltf", *FAST]
    p = cli(args, tmp)
    if p.returncode == 0 and "secret.png" in (tmp / "out" / "m.gltf").read_text():
        return "OUTSIDE (the copy names ../secret.png)"
    return classify(p, tmp / "out")


def mitsuba_include_outside(tmp: Path) -> str:
    (tmp / "lib.xml").write_text('<scene version="3.0.0"><bsdf type="diffuse" id="d"/></scene>')
    (tmp / "asset").mkdir()
    (tmp / "asset" / "s.xml").write_text('<scene version="3.0.0"><include filename="../lib.xml"/></scene>')
    return classify(cli(["remap", "asset/s.xml", "--to", "mitsuba06:diffuse", "-o", "out"], tmp), tmp / "out")


def materialx_xinclude(tmp: Path) -> str:
    (tmp / "lib.mtlx").write_text('<?xml version="1.0"?>\n<materialx version="1.39"/>\n')
    png(tmp / "asset" / "base.png", gradient())
    text = materialx_file_doc("base.png").replace(
        '<materialx version="1.39">',
        '<materialx version="1.39" xmlns:xi="http://www.w3.org/2001/XInclude"><xi:include href="../lib.mtlx"/>',
    )
    (tmp / "asset" / "m.mtlx").write_text(text)
    return classify(cli(["remap", "asset/m.mtlx", "--to", "gltf:metal-rough", "-o", "out"], tmp), tmp / "out")


def materialx_file_doc(ref: str, prefix: str = "") -> str:
    pre = f' fileprefix="{prefix}"' if prefix else ""
    return (
        f'<?xml version="1.0"?>\n<materialx version="1.39"{pre}>\n'
        f'  <image name="tex" type="color3"><input name="file" type="filename" value="{ref}"/></image>\n'
        '  <standard_surface name="s" type="surfaceshader"><input name="base_color" type="color3" nodename="tex"/>'
        "</standard_surface>\n"
        '  <surfacematerial name="mat" type="material"><input name="surfaceshader" type="surfaceshader" nodename="s"/>'
        "</surfacematerial>\n</materialx>\n"
    )


def materialx_fileprefix(tmp: Path) -> str:
    secret_png(tmp / "secret.png")
    (tmp / "asset").mkdir()
    (tmp / "asset" / "m.mtlx").write_text(materialx_file_doc("secret.png", prefix="../"))
    return classify(cli(["remap", "asset/m.mtlx", "--to", "gltf:metal-rough", "-o", "out"], tmp), tmp / "out")


USD_MATERIAL = """#usda 1.0
def Xform "Root"
{{
    def Shader "ST"
    {{
        uniform token info:id = "UsdPrimvarReader_float2"
        token inputs:varname = "st"
        float2 outputs:result
    }}
    def Material "A"
    {{
        token outputs:surface.connect = </Root/A/S.outputs:surface>
        def Shader "S"
        {{
            uniform token info:id = "UsdPreviewSurface"
            color3f inputs:diffuseColor.connect = </Root/A/T.outputs:rgb>
            float inputs:roughness = 0.5
            token outputs:surface
        }}
        def Shader "T"
        {{
            uniform token info:id = "UsdUVTexture"
            asset inputs:file = @{tex}@
            float2 inputs:st.connect = </Root/ST.outputs:result>
            float3 outputs:rgb
        }}
    }}{more}
}}
"""


def usd_texture_outside(tmp: Path) -> str:
    secret_png(tmp / "secret.png")
    (tmp / "asset").mkdir()
    (tmp / "asset" / "m.usda").write_text(USD_MATERIAL.format(tex="../secret.png", more=""))
    return classify(cli(["remap", "asset/m.usda", "--to", "gltf:metal-rough", "-o", "out"], tmp), tmp / "out")


def usd_copy_other_texture_outside(tmp: Path) -> str:
    """--write m.usdz of material A: material B's texture is ../secret.png (a .usdz packs what a stage names)."""
    secret_png(tmp / "secret.png")
    png(tmp / "asset" / "base.png", gradient())
    other = USD_MATERIAL.format(tex="../secret.png", more="").split('def Material "A"', 1)[1].rsplit("}", 1)[0]
    more = '\n    def Material "B"' + other.replace("/Root/A/", "/Root/B/").rstrip()
    (tmp / "asset" / "m.usda").write_text(USD_MATERIAL.format(tex="base.png", more=more))
    args = ["remap", "asset/m.usda", "--material", "/Root/A", "--to", "usd:preview_surface", "-o", "out"]
    return classify(cli([*args, "--write", "m.usdz", *FAST], tmp), tmp / "out")


def usd_value_clip_outside(tmp: Path) -> str:
    """A value clip naming ../clip.usda: USD opened it while matremap read the stage (not a composition arc)."""
    (tmp / "clip.usda").write_text('#usda 1.0\ndef Xform "Root"\n{\n}\n')
    png(tmp / "asset" / "base.png", gradient())
    clips = (
        "(\n    clips = {\n        dictionary default = {\n            asset[] assetPaths = [@../clip.usda@]\n"
        '            double2[] active = [(0, 0)]\n            string primPath = "/Root"\n        }\n    }\n)\n'
    )
    text = USD_MATERIAL.format(tex="base.png", more="").replace('def Xform "Root"\n', 'def Xform "Root"\n' + clips)
    (tmp / "asset" / "m.usda").write_text(text)
    return classify(cli(["remap", "asset/m.usda", "--to", "gltf:metal-rough", "-o", "out", *FAST], tmp), tmp / "out")


def usdz_member_outside(tmp: Path) -> str:
    import zipfile

    secret_png(tmp / "secret.png")
    (tmp / "asset").mkdir()
    with zipfile.ZipFile(tmp / "asset" / "m.usdz", "w", zipfile.ZIP_STORED) as z:
        z.writestr("m.usda", USD_MATERIAL.format(tex="../../secret.png", more=""))
    return classify(cli(["remap", "asset/m.usdz", "--to", "gltf:metal-rough", "-o", "out"], tmp), tmp / "out")


def map_set_manifest_outside(tmp: Path) -> str:
    png(tmp / "secret.png", np.full((256, 256, 3), 0.4))  # the example's size
    with (tmp / "secret.png").open("ab") as f:
        f.write(SECRET)
    maps = bronze_balanced(tmp)
    doc = json.loads((maps / "material.json").read_text())
    doc["maps"]["diffuseReflectance"] = "../secret.png"
    (maps / "material.json").write_text(json.dumps(doc))
    transform = str(ROOT / "src" / "matremap" / "regress" / "transforms" / "ward-as.json")
    return classify(cli(["convert", str(maps), "--transform", transform, "-o", "out"], tmp), tmp / "out")


def glb_cache_forged(tmp: Path) -> str:
    """A .glb's embedded image is extracted to a cache; a same-size forged file put there must not be used,
    and the written map set must not point into the cache (finding 2)."""
    import OpenImageIO as oiio

    png(tmp / "a.png", np.full((8, 8, 3), [0.8, 0.2, 0.1]))
    data = (tmp / "a.png").read_bytes()
    body = {
        "asset": {"version": "2.0"},
        "buffers": [{"byteLength": len(data)}],
        "bufferViews": [{"buffer": 0, "byteLength": len(data)}],
        "images": [{"bufferView": 0, "mimeType": "image/png"}],
        "textures": [{"source": 0}],
        "materials": [{"name": "m", "pbrMetallicRoughness": {"baseColorTexture": {"index": 0}, "metallicFactor": 0}}],
    }
    text = json.dumps(body).encode()
    text += b" " * (-len(text) % 4)
    binc = data + b"\0" * (-len(data) % 4)
    chunks = len(text).to_bytes(4, "little") + b"JSON" + text + len(binc).to_bytes(4, "little") + b"BIN\0" + binc
    (tmp / "m.glb").write_bytes(b"glTF" + (2).to_bytes(4, "little") + (12 + len(chunks)).to_bytes(4, "little") + chunks)
    args = ["remap", "m.glb", "--to", "gltf:metal-rough", "-o", "out1", *FAST]
    if (p := cli(args, tmp)).returncode != 0:
        return f"setup failed: {p.stderr.strip()[-80:]}"
    manifest = (tmp / "out1" / "maps" / "material.json").read_text()
    if str(tmp / "cache") in manifest or tempfile.gettempdir() in manifest:
        return "WRONG (the map set points into the cache)"
    png(tmp / "b.png", np.full((8, 8, 3), [0.1, 0.2, 0.8]))
    forged = (tmp / "b.png").read_bytes()
    forged += b"\0" * (len(data) - len(forged))  # bytes after IEND: readers ignore them
    places = [Path(tempfile.gettempdir()), tmp / "cache"]
    found = [f for d in places for f in d.rglob("*.png") if f.is_file() and f.stat().st_size == len(data)]
    hits = [f for f in found if tmp / "cache" in f.parents or tmp not in f.parents]  # not the case's own files
    if not hits:
        return "setup failed: the extracted image is nowhere"
    for f in hits:  # the same size, other pixels
        f.write_bytes(forged)
    p = cli([*args[: -len(FAST) - 1], "out2", *FAST], tmp)
    if p.returncode != 0:
        return f"exit {p.returncode}"
    truth = oiio.ImageBuf(str(tmp / "a.png")).get_pixels().tobytes()  # the same model: maps are copied
    kept = [
        any(oiio.ImageBuf(str(f)).get_pixels().tobytes() == truth for f in (tmp / o / "maps").glob("*.png"))
        for o in ("out1", "out2")
    ]
    return "handled" if all(kept) else "WRONG (a forged or stale cache file was used)"


def cached_transform_edited(tmp: Path) -> str:
    """A swept and learned transform is cached; its coefficients edited, the next run must not use it."""
    import OpenImageIO as oiio

    args = ["remap", str(ROOT / "examples" / "bronze"), "--to", "mitsuba06:pbr", "--fix", "distribution=as"]
    args += ["--sweep", *FAST]
    if (p := cli([*args, "-o", "out1"], tmp)).returncode not in (0, 3):
        return f"setup failed: {p.stderr.strip()[-80:]}"
    cached = [f for f in (tmp / "cache").rglob("*.json") if "mappings" in f.read_text()]
    if not cached:
        return "setup failed: no cached transform"
    for f in cached:
        doc = json.loads(f.read_text())
        for m in doc["mappings"].values():
            m["coef"] = [0.0] * len(m["coef"])
        f.write_text(json.dumps(doc))
    p = cli([*args, "-o", "out2"], tmp)
    maps = [sorted((tmp / o / "maps").glob("*.png")) for o in ("out1", "out2")]
    same = [
        oiio.ImageBuf(str(a)).get_pixels().tobytes() == oiio.ImageBuf(str(b)).get_pixels().tobytes()
        for a, b in zip(*maps, strict=False)
    ]
    if p.returncode in (0, 3) and maps[0] and all(same) and len(maps[0]) == len(maps[1]):
        return "handled"
    return f"WRONG (exit {p.returncode}, edited transform used)" if p.returncode in (0, 3) else f"exit {p.returncode}"


def cached_sweep_damaged(tmp: Path) -> str:
    """The sweep database the transform cache keeps (resumed when its transform is gone), a page damaged."""
    args = ["remap", str(ROOT / "examples" / "bronze"), "--to", "mitsuba06:pbr", "--fix", "distribution=as"]
    args += ["--sweep", "--no-evaluate"]
    if (p := cli([*args, "-o", "out1"], tmp)).returncode not in (0, 3):
        return f"setup failed: {p.stderr.strip()[-80:]}"
    for f in (tmp / "cache").rglob("*.json"):
        if "mappings" in f.read_text():
            f.unlink()
    dbs = list((tmp / "cache").rglob("*.sqlite"))
    if not dbs:
        return "setup failed: no cached sweep database"
    for db in dbs:
        data = bytearray(db.read_bytes())
        start = len(data) // 2 // 4096 * 4096
        data[start : start + 4096] = b"A" * 4096
        db.write_bytes(bytes(data))
    p = cli([*args, "-o", "out2"], tmp)
    if "Traceback" in p.stderr:
        return "TRACEBACK"
    return "handled" if p.returncode in (0, 3) else f"exit {p.returncode}"


def uniform_texture(tmp: Path) -> str:
    """A glTF whose base colour texture is one colour, onto another model (a legitimate file)."""
    src = textured_gltf(tmp / "asset", "base.png")
    png(tmp / "asset" / "base.png", np.full((8, 8, 3), 0.5))
    p = cli(["remap", str(src), "--to", "mitsuba06:ward", "-o", "out", *FAST], tmp)
    if "Traceback" in p.stderr:
        return "TRACEBACK"
    return "handled" if p.returncode in (0, 3) else f"exit {p.returncode}"


def cached_table_damaged(tmp: Path) -> str:
    """A numerically integrated table in the cache with a byte flipped (finding 2: verified on load)."""
    src = "cycles:glossy,distribution=multi_ggx,Roughness=0.4"
    if (p := cli(["render", src, "-o", "a.png", "--size", "16"], tmp)).returncode != 0:
        return f"setup failed: {p.stderr.strip()[-80:]}"
    tables = list((tmp / "cache").rglob("*.npz"))
    if not tables:
        return "setup failed: no table cached"
    for t in tables:
        data = bytearray(t.read_bytes())
        data[len(data) // 2] ^= 0xFF
        t.write_bytes(bytes(data))
    p = cli(["render", src, "-o", "b.png", "--size", "16"], tmp)
    if "Traceback" in p.stderr:
        return "TRACEBACK"
    same = (tmp / "a.png").read_bytes() == (tmp / "b.png").read_bytes() if p.returncode == 0 else False
    return "handled" if same else f"exit {p.returncode}: {(p.stderr.strip().splitlines() or [''])[-1][:60]}"


def failed_points_refitted(tmp: Path) -> str:
    """A point recorded as failed (its renderer was missing) is fitted again when the sweep resumes (finding 3)."""
    import sqlite3

    args = ["sweep", "--source", SWEEP_SOURCE, "--to", "mitsuba06:pbr", "--grid", "alpha=0.1:0.3:3"]
    args += ["--db", "s.sqlite", "--workers", "1", "--no-progress"]
    if (p := cli(args, tmp)).returncode != 0:
        return f"setup failed: {p.stderr.strip()[-80:]}"
    with sqlite3.connect(tmp / "s.sqlite") as con:
        con.execute("update points set status = 'failed', message = 'RendererNotInstalled' where rowid = 1")
    p = cli(args, tmp)
    with sqlite3.connect(tmp / "s.sqlite") as con:
        bad = con.execute("select count(*) from points where status != 'ok'").fetchone()[0]
    return "handled" if p.returncode == 0 and bad == 0 else f"WRONG ({bad} failed point(s) kept, exit {p.returncode})"


def transform_edit(tmp: Path, edit: Callable[[dict], None]) -> str:
    doc = json.loads((ROOT / "src" / "matremap" / "regress" / "transforms" / "ward-as.json").read_text())
    doc.pop("checksum", None)  # a hand-made transform: only its schema can stop it
    edit(doc)
    (tmp / "t.json").write_text(json.dumps(doc))
    p = cli(["convert", str(bronze_balanced(tmp)), "--transform", "t.json", "-o", "out"], tmp)
    return classify(p, tmp / "out")


def bronze_balanced(tmp: Path) -> Path:
    """``examples/bronze`` with the Ward variant the shipped ward-as transform was learned on (an older
    matremap refused the example's variant first, before looking at the transform)."""
    shutil.copytree(ROOT / "examples" / "bronze", tmp / "bronze")
    doc = json.loads((tmp / "bronze" / "material.json").read_text())
    doc["params"]["variant"] = "balanced"
    (tmp / "bronze" / "material.json").write_text(json.dumps(doc))
    return tmp / "bronze"


def transform_string_coef(tmp: Path) -> str:
    return transform_edit(tmp, lambda d: d["mappings"]["roughness"].update(coef=["0.5"] * 5))


def transform_coef_count(tmp: Path) -> str:
    return transform_edit(tmp, lambda d: d["mappings"]["reflectance"].update(coef=[1.0, 2.0]))


def transform_huge_constant(tmp: Path) -> str:
    return transform_edit(tmp, lambda d: d["mappings"]["roughness"].update(coef=[1e300, 0, 0, 0, 0]))


def transform_unknown_option(tmp: Path) -> str:
    return transform_edit(tmp, lambda d: d["target"]["options"].update(distribution="nonsense"))


def transform_deep(tmp: Path) -> str:
    (tmp / "t.json").write_text('{"schema": ' + "[" * 100_000 + "]" * 100_000 + "}")
    p = cli(["convert", str(ROOT / "examples" / "bronze"), "--transform", "t.json", "-o", "out"], tmp)
    return classify(p, tmp / "out")


def glb_string_offset(tmp: Path) -> str:
    data = (ROOT / "examples" / "bronze" / "bronze_diffuse.png").read_bytes()
    body = {
        "asset": {"version": "2.0"},
        "buffers": [{"byteLength": len(data)}],
        "bufferViews": [{"buffer": 0, "byteOffset": "0", "byteLength": len(data)}],
        "images": [{"bufferView": 0, "mimeType": "image/png"}],
        "textures": [{"source": 0}],
        "materials": [{"name": "m", "pbrMetallicRoughness": {"baseColorTexture": {"index": 0}}}],
    }
    text = json.dumps(body).encode()
    text += b" " * (-len(text) % 4)
    binc = data + b"\0" * (-len(data) % 4)
    chunks = len(text).to_bytes(4, "little") + b"JSON" + text + len(binc).to_bytes(4, "little") + b"BIN\0" + binc
    (tmp / "m.glb").write_bytes(b"glTF" + (2).to_bytes(4, "little") + (12 + len(chunks)).to_bytes(4, "little") + chunks)
    return classify(cli(["remap", "m.glb", "--to", "mitsuba06:ward", "-o", "out"], tmp), tmp / "out")


def material_json_deep(tmp: Path) -> str:
    (tmp / "m.json").write_text('{"model": "mitsuba06:ward", "params": ' + "[" * 100_000 + "]" * 100_000 + "}")
    p = cli(["fit", "--source", "m.json", "--to", "mitsuba06:pbr"], tmp)
    return classify(p, tmp / "out")


def manifest_deep(tmp: Path) -> str:
    shutil.copytree(ROOT / "examples" / "bronze", tmp / "maps")
    (tmp / "maps" / "material.json").write_text(
        '{"model": "mitsuba06:ward", "maps": ' + "[" * 100_000 + "]" * 100_000 + "}"
    )
    return classify(
        cli(["convert", "maps", "--to", "mitsuba06:pbr", "--fix", "distribution=as", "-o", "out"], tmp), tmp / "out"
    )


def sweep_db_edit(tmp: Path, sql: str) -> str:
    import sqlite3

    args = ["sweep", "--source", SWEEP_SOURCE, "--to", "mitsuba06:pbr", "--grid", "alpha=0.1:0.3:3"]
    if (p := cli([*args, "--db", "s.sqlite", "--workers", "1", "--no-progress"], tmp)).returncode != 0:
        return f"setup failed: {p.stderr.strip()[-80:]}"
    with sqlite3.connect(tmp / "s.sqlite") as con:
        con.execute(sql)
    return classify(cli(["learn", "s.sqlite", "-o", "t.json"], tmp), tmp / "t.json")


def sweep_db_bad_json(tmp: Path) -> str:
    return sweep_db_edit(tmp, "update points set target = '{not json' where rowid = 1")


def sweep_db_dropped_column(tmp: Path) -> str:
    return sweep_db_edit(tmp, "alter table points drop column loss")


def two_sweeps_new_db(tmp: Path) -> str:
    """Two sweeps with different settings start on one new database at once (finding 8)."""
    outcomes = set()
    for i in range(4):
        db = f"race{i}.sqlite"
        procs = []
        for strategy in ("two-stage", "simple"):
            args = ["sweep", "--source", SWEEP_SOURCE, "--to", "mitsuba06:pbr", "--grid", "alpha=0.1:0.3:2"]
            args += ["--db", db, "--workers", "1", "--no-progress", "--strategy", strategy]
            env = {**os.environ, "MATREMAP_CACHE": str(tmp / "cache")}
            procs.append(
                subprocess.Popen(
                    [sys.executable, "-m", MODULE, *spelled(args)],
                    cwd=tmp,
                    env=env,
                    stdout=subprocess.DEVNULL,
                    stderr=subprocess.PIPE,
                    text=True,
                )
            )
        for proc in procs:
            err = proc.communicate(timeout=300)[1]
            if "Traceback" in err:
                return "TRACEBACK"
            if proc.returncode != 0:
                last = (err.strip().splitlines() or [""])[-1]
                outcomes.add("handled" if "different configuration" in last else f"misleading: {last[:60]}")
    return ", ".join(sorted(outcomes)) or "both ran (no loser)"


def absurd_png_header(tmp: Path) -> str:
    """A map whose header claims 40000 x 40000 (finding 4: refused from its header, not decoded)."""
    import struct
    import zlib

    def chunk(kind: bytes, data: bytes) -> bytes:
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))

    shutil.copytree(ROOT / "examples" / "bronze", tmp / "maps")
    ihdr = struct.pack(">IIBBBBB", 40000, 40000, 8, 2, 0, 0, 0)
    (tmp / "maps" / "bronze_roughness.png").write_bytes(
        b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", ihdr) + chunk(b"IDAT", zlib.compress(b"\0" * 1000)) + chunk(b"IEND", b"")
    )
    args = ["remap", "maps", "--to", "mitsuba06:pbr", "--fix", "distribution=as", "-o", "out", *FAST]
    return classify(cli(args, tmp, timeout=600), tmp / "out")


# -- interruption (finding 8, must-have 6): kill or interrupt a run, then run the same command again ----------

FAST = ["--rotations", "0:360:2", "--size", "48", "--env-lights", "32"]
SWEEP_SOURCE = json.dumps({"model": "mitsuba06:ward", "params": {"alpha": 0.2, "specularReflectance": 0.05}})


def bronze_tiled(folder: Path, size: int = 1024) -> Path:
    """``examples/bronze`` tiled to ``size`` x ``size``: big enough to be caught while it is written."""
    import OpenImageIO as oiio

    shutil.copytree(ROOT / "examples" / "bronze", folder, ignore=shutil.ignore_patterns("*.png"))
    for f in sorted((ROOT / "examples" / "bronze").glob("*.png")):
        inp = oiio.ImageInput.open(str(f))
        spec = inp.spec()
        tile = np.asarray(inp.read_image(0, 0, 0, spec.nchannels, "uint8")).reshape(spec.height, spec.width, -1)
        inp.close()
        reps = size // spec.width
        png_out = oiio.ImageOutput.create(str(folder / f.name))
        png_out.open(str(folder / f.name), oiio.ImageSpec(size, size, spec.nchannels, "uint8"))
        png_out.write_image(np.ascontiguousarray(np.tile(tile, (reps, reps, 1))))
        png_out.close()
    return folder


def hidden(tmp: Path) -> list[Path]:
    """Hidden files and folders (staging, temporary files) anywhere under ``tmp``, the cache and the output
    record of a finished folder (``.matremap.json``) aside."""
    return [f for f in tmp.rglob(".*") if "cache" not in f.relative_to(tmp).parts and f.name != ".matremap.json"]


def staging_started(tmp: Path) -> bool:
    return bool(hidden(tmp))


def mid_write(tmp: Path) -> bool:
    """A file being written inside a hidden (staging) folder or under a hidden name, with bytes in it."""
    return any(f.is_file() and f.stat().st_size > 0 for h in hidden(tmp) for f in [h, *h.rglob("*")])


def db_started(tmp: Path) -> bool:
    import sqlite3

    db = tmp / "s.sqlite"
    if not db.is_file():
        return False
    try:
        with sqlite3.connect(db, timeout=0.1) as con:
            return con.execute("select count(*) from points").fetchone()[0] >= 1
    except sqlite3.Error:
        return False


def tree(folder: Path) -> dict[str, object]:
    """Every visible file under ``folder``: relative name -> its pixels (images: their headers carry the
    time of writing) or bytes; the report's HTML and JSON aside (they carry timings)."""
    import OpenImageIO as oiio

    if not folder.is_dir():
        return {}
    out: dict[str, object] = {}
    for f in sorted(folder.rglob("*")):
        rel = f.relative_to(folder)
        if not f.is_file() or any(p.startswith(".") for p in rel.parts) or f.suffix in (".html", ".json"):
            continue
        if f.suffix.lower() in (".exr", ".png", ".tif", ".jpg"):
            out[str(rel)] = oiio.ImageBuf(str(f)).get_pixels().tobytes()
        else:
            out[str(rel)] = f.read_bytes()
    return out


def interrupted(tmp: Path, args: list[str], sig: int, point: Callable[[Path], bool], out: str) -> str:
    """Run ``matremap ARGS`` in ``tmp``, send ``sig`` (SIGINT to the process group, as Ctrl-C does) when
    ``point`` holds, then run the same command again; compare with an uninterrupted run. ``out``: the
    output (folder or database) that the command writes, relative to ``tmp``."""
    ref = tmp / "ref"
    ref.mkdir()
    if (p := cli(args, ref)).returncode != 0:
        return f"setup failed: {p.stderr.strip()[-80:]}"
    run = tmp / "run"
    run.mkdir()
    env = {**os.environ, "MATREMAP_CACHE_DIR": str(run / "cache"), "MATREMAP_CACHE": str(run / "cache")}
    with open(tmp / "stderr.txt", "w+") as log:  # a file, not a pipe: workers a kill orphans may hold it open
        proc = subprocess.Popen(
            [sys.executable, "-m", MODULE, *spelled(args)],
            cwd=run,
            env=env,
            stdout=subprocess.DEVNULL,
            stderr=log,
            text=True,
            start_new_session=True,
            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL),  # a background shell ignores SIGINT
        )
        deadline = time.time() + 120
        while time.time() < deadline and proc.poll() is None and not point(run):
            time.sleep(0.005)
        if proc.poll() is not None:
            return "finished before the signal"
        os.killpg(proc.pid, sig) if sig == signal.SIGINT else proc.send_signal(sig)
        proc.wait(timeout=120)
        log.seek(0)
        err = log.read()
    if sig == signal.SIGINT:
        if "Traceback" in err:
            return "TRACEBACK on SIGINT"
        last = (err.strip().splitlines() or [""])[-1]
        said = last == "matremap: interrupted" or (args[0] == "sweep" and last.startswith("interrupted: "))
        if proc.returncode != 130 or not said:  # a sweep stopped between points says how far it got
            return f"SIGINT: exit {proc.returncode}, {last!r}"
    again = cli(args, run)
    if again.returncode != 0:
        return f"rerun exit {again.returncode}: {again.stderr.strip().splitlines()[-1][:70]}"
    left = hidden(run)
    if left:
        return f"LEFTOVER ({', '.join(sorted({f.name.split('-')[0] + '-...' for f in left})[:2])})"
    if out.endswith(".sqlite"):
        rows = cli(["export", out, "-o", "t.csv"], run), cli(["export", out, "-o", "t.csv"], ref)
        same = (run / "t.csv").read_text().count("\n") == (ref / "t.csv").read_text().count("\n")
        return "handled" if all(r.returncode == 0 for r in rows) and same else "WRONG (rows differ)"
    return "handled" if tree(run / out) == tree(ref / out) else "WRONG (result differs from a clean run)"


def convert_killed_leftovers(tmp: Path) -> str:
    src = str(bronze_tiled(tmp / "maps"))
    args = ["convert", src, "--to", "mitsuba06:pbr", "--fix", "distribution=as", "-o", "out"]
    return interrupted(tmp, args, signal.SIGKILL, staging_started, "out")


def convert_killed_mid_write(tmp: Path) -> str:
    src = str(bronze_tiled(tmp / "maps"))
    args = ["convert", src, "--to", "mitsuba06:pbr", "--fix", "distribution=as", "-o", "out"]
    return interrupted(tmp, args, signal.SIGKILL, mid_write, "out")


def convert_sigint(tmp: Path) -> str:
    src = str(bronze_tiled(tmp / "maps"))
    args = ["convert", src, "--to", "mitsuba06:pbr", "--fix", "distribution=as", "-o", "out"]
    return interrupted(tmp, args, signal.SIGINT, mid_write, "out")


def remap_maps_killed(tmp: Path) -> str:
    src = str(bronze_tiled(tmp / "maps"))
    args = ["remap", src, "--to", "mitsuba06:pbr", "--fix", "distribution=as", "-o", "out", *FAST]
    return interrupted(tmp, args, signal.SIGKILL, mid_write, "out")


def remap_maps_sigint(tmp: Path) -> str:
    src = str(bronze_tiled(tmp / "maps"))
    args = ["remap", src, "--to", "mitsuba06:pbr", "--fix", "distribution=as", "-o", "out", *FAST]
    return interrupted(tmp, args, signal.SIGINT, mid_write, "out")


def remap_file_killed(tmp: Path) -> str:
    src = str(ROOT / "examples" / "brass-gltf" / "brass.gltf")
    args = ["remap", src, "--to", "mitsuba3:roughconductor", "--fix", "distribution=ggx", "-o", "out", *FAST]
    return interrupted(tmp, args, signal.SIGKILL, mid_write, "out")


def sweep_killed(tmp: Path) -> str:
    args = ["sweep", "--source", SWEEP_SOURCE, "--to", "mitsuba06:pbr", "--grid", "alpha=0.1:0.3:6"]
    args += ["--db", "s.sqlite", "--workers", "2", "--no-progress"]
    return interrupted(tmp, args, signal.SIGKILL, db_started, "s.sqlite")


def sweep_sigint(tmp: Path) -> str:
    args = ["sweep", "--source", SWEEP_SOURCE, "--to", "mitsuba06:pbr", "--grid", "alpha=0.1:0.3:6"]
    args += ["--db", "s.sqlite", "--workers", "2", "--no-progress"]
    return interrupted(tmp, args, signal.SIGINT, db_started, "s.sqlite")


# -- outputs and --force ----------------------------------------------------------------------------------


def files_under(folder: Path) -> dict[str, bytes]:
    return {q.relative_to(folder).as_posix(): q.read_bytes() for q in sorted(folder.rglob("*")) if q.is_file()}


def kept(tmp: Path, project: Path, args: list[str]) -> str:
    """Run ``args`` in ``tmp``: ``refused`` when it exits 2 and every file of ``project`` is as it was,
    ``DATA LOSS`` when one went missing or changed."""
    before = files_under(project)
    p = cli(args, tmp)
    if "Traceback (most recent call last)" in p.stderr:
        return "TRACEBACK"
    after = files_under(project) if project.exists() else {}
    if any(after.get(k) != v for k, v in before.items()):
        return "DATA LOSS"
    return "refused" if p.returncode == 2 else f"exit {p.returncode}"


def user_project(tmp: Path) -> Path:
    """``proj/in/m.gltf`` with its texture in ``proj/in/tex``, beside other work of the user's."""
    textured_gltf(tmp / "proj" / "in", "tex/base.png")
    (tmp / "proj" / "in" / "tex").mkdir()
    (tmp / "proj" / "in" / "base.png").rename(tmp / "proj" / "in" / "tex" / "base.png")
    (tmp / "proj" / "notes.txt").write_text("the user's notes")
    return tmp / "proj"


def force_above_input(tmp: Path) -> str:
    proj = user_project(tmp)
    return kept(tmp, proj, ["remap", "proj/in/m.gltf", "--to", "mitsuba06:ward", "-o", "proj", "--force"])


def force_on_texture_folder(tmp: Path) -> str:
    proj = user_project(tmp)
    return kept(tmp, proj, ["remap", "proj/in/m.gltf", "--to", "mitsuba06:ward", "-o", "proj/in/tex", "--force"])


def force_above_map_set(tmp: Path) -> str:
    shutil.copytree(ROOT / "examples" / "blue-plastic", tmp / "proj" / "maps")
    (tmp / "proj" / "notes.txt").write_text("the user's notes")
    return kept(tmp, tmp / "proj", ["remap", "proj/maps", "--to", "mitsuba06:pbr", "-o", "proj", "--force"])


def force_on_users_folder(tmp: Path) -> str:
    user_project(tmp)
    (tmp / "work").mkdir()
    (tmp / "work" / "keep.txt").write_text("mine")
    return kept(tmp, tmp / "work", ["remap", "proj/in/m.gltf", "--to", "gltf:metal-rough", "-o", "work", "--force"])


def force_on_cache(tmp: Path) -> str:
    user_project(tmp)
    (tmp / "cache" / "transforms").mkdir(parents=True)
    (tmp / "cache" / "transforms" / "t.json").write_text("{}")
    return kept(tmp, tmp / "cache", ["remap", "proj/in/m.gltf", "--to", "gltf:metal-rough", "-o", "cache", "--force"])


def cache_sweep_started(tmp: Path) -> bool:
    """Whether a sweep database in the transform cache holds a fitted point."""
    import sqlite3

    for db in (tmp / "cache").rglob("*.sqlite"):
        try:
            with sqlite3.connect(db, timeout=0.1) as con:
                if con.execute("select count(*) from points").fetchone()[0] >= 1:
                    return True
        except sqlite3.Error:
            continue
    return False


def remap_sweep_sigint(tmp: Path) -> str:
    args = ["remap", str(ROOT / "examples" / "bronze"), "--to", "mitsuba06:pbr", "--fix", "distribution=as"]
    args += ["-o", "out", "--sweep", "--no-evaluate", "--workers", "1"]
    return interrupted(tmp, args, signal.SIGINT, cache_sweep_started, "out")


def two_remaps_one_cache(tmp: Path) -> str:
    """Two remaps needing the same transform at once: ``handled`` when one sweeps and the other waits for it."""
    env = {**os.environ, "MATREMAP_CACHE_DIR": str(tmp / "cache"), "MATREMAP_CACHE": str(tmp / "cache")}
    args = ["remap", str(ROOT / "examples" / "bronze"), "--to", "mitsuba06:pbr", "--fix", "distribution=as"]
    args += ["--sweep", "--no-evaluate", "--workers", "1"]
    runs = [
        subprocess.Popen(
            [sys.executable, "-m", MODULE, *spelled([*args, "-o", f"out{i}"])],
            cwd=tmp,
            env=env,
            stdout=subprocess.DEVNULL,
            stderr=subprocess.PIPE,
            text=True,
        )
        for i in range(2)
    ]
    errs = [r.communicate(timeout=900)[1] for r in runs]
    if any(r.returncode != 0 for r in runs):
        return f"exit {[r.returncode for r in runs]}"
    swept = sum("points fitted" in e for e in errs)
    return "handled" if swept == 1 else f"SWEPT TWICE ({swept} sweeps)"


# -- second round: batches (change detection, their own folders, concurrent runs, orphans, leftovers) ------------

BATCH_SCENE = (
    '<scene version="3.0.0">\n'
    '  <bsdf type="diffuse" id="wall"><rgb name="reflectance" value="0.6, 0.5, 0.4"/></bsdf>\n'
    '  <bsdf type="roughconductor" id="steel"><string name="material" value="Cr"/>'
    '<float name="alpha" value="0.2"/></bsdf>\n'
    "</scene>\n"
)


def limited_memory() -> None:
    """In a batch's process: at most 4 GB of address space (an unbounded read fails, not the machine)."""
    import resource

    resource.setrlimit(resource.RLIMIT_AS, (4 << 30, 4 << 30))


def batch_run(args: list[str], cwd: Path, timeout: float = 300) -> subprocess.CompletedProcess[str] | str:
    """A batch (``matremap remap ARGS FAST``) in ``cwd``, its memory bounded; "HANGS" when it outlives ``timeout``."""
    env = {**os.environ, "MATREMAP_CACHE": str(cwd / "cache")}
    try:
        p = subprocess.run(
            [sys.executable, "-m", MODULE, *spelled([*args, *FAST])],
            cwd=cwd,
            env=env,
            capture_output=True,
            text=True,
            timeout=timeout,
            preexec_fn=limited_memory,
        )
    except subprocess.TimeoutExpired:
        return f"HANGS (> {timeout:.0f} s)"
    LAST[0] = (p.stderr.strip().splitlines() or [""])[-1].replace(str(cwd), "T")
    return p


def batch_gltf(folder: Path, names: list[str], uris: tuple[str, ...] = ()) -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    pbr = {"baseColorFactor": [0.8, 0.1, 0.1, 1], "metallicFactor": 0.0, "roughnessFactor": 0.5}
    doc = {
        "asset": {"version": "2.0"},
        "images": [{"uri": u} for u in uris],
        "materials": [{"name": n, "pbrMetallicRoughness": pbr} for n in names],
    }
    (folder / "m.gltf").write_text(json.dumps(doc))
    return folder / "m.gltf"


def batch_done(p: subprocess.CompletedProcess[str] | str, unchanged: int | None = None) -> str:
    """``handled`` for a batch that converted (exit 0 or 3) with a summary (and ``unchanged`` items skipped)."""
    if isinstance(p, str):
        return p
    if "Traceback" in p.stderr:
        return "TRACEBACK"
    if p.returncode not in (0, 3):
        return f"exit {p.returncode}"
    if unchanged is not None and f"({unchanged} unchanged, not redone)" not in p.stdout:
        return "REDONE (" + (p.stdout.strip().splitlines() or [""])[-1].split("(")[-1][:40]
    return "handled"


def batch_fifo(tmp: Path) -> str:
    """A FIFO named like a word of the material file (its image) in the batch's folder: the key opened it."""
    batch_gltf(tmp / "in", ["a", "b"], ("base.png",))
    os.mkfifo(tmp / "in" / "base.png")
    return batch_done(batch_run(["remap", "in", "--to", "mitsuba06:ward", "-o", "out"], tmp, timeout=120))


def batch_dev_zero(tmp: Path) -> str:
    """A link to /dev/zero named by the material: the key read it without end (5.4 GB in 4 s)."""
    batch_gltf(tmp / "in", ["a", "b"], ("base.png",))
    (tmp / "in" / "base.png").symlink_to("/dev/zero")
    return batch_done(batch_run(["remap", "in", "--to", "mitsuba06:ward", "-o", "out"], tmp, timeout=120))


def batch_link_outside(tmp: Path) -> str:
    """A link out of the asset folder named by the material: its target (outside) decided the key."""
    (tmp / "secret.png").write_bytes(SECRET)
    batch_gltf(tmp / "in", ["a", "b"], ("base.png",))
    (tmp / "in" / "base.png").symlink_to(tmp / "secret.png")
    args = ["remap", "in", "--to", "mitsuba06:ward", "-o", "out"]
    if (first := batch_done(batch_run(args, tmp))) != "handled":
        return first
    (tmp / "secret.png").write_bytes(SECRET + b"edited")
    outcome = batch_done(batch_run(args, tmp), unchanged=2)
    return "READ OUTSIDE (" + outcome + ")" if outcome.startswith("REDONE") else outcome


def batch_non_utf8_name(tmp: Path) -> str:
    (tmp / "in").mkdir()
    (Path(os.fsdecode(os.fsencode(tmp / "in") + b"/sc\xe9ne.xml"))).write_text(BATCH_SCENE)
    p = batch_run(["remap", "in", "--to", "mitsuba06:ward", "-o", "out"], tmp)
    outcome = batch_done(p)
    if outcome == "handled" and not (tmp / "out" / "summary.csv").is_file():
        return "no summary"
    return outcome


def batch_invalid_escape(tmp: Path) -> str:
    (tmp / "in").mkdir()
    pbr = '"pbrMetallicRoughness": {"baseColorFactor": [0.8, 0.1, 0.1, 1], "metallicFactor": 0.0}'
    (tmp / "in" / "m.gltf").write_text(
        '{"asset": {"version": "2.0"}, "materials": [{"name": "bad \\ud800", '
        + pbr
        + '}, {"name": "ok", '
        + pbr
        + "}]}"
    )
    outcome = batch_done(batch_run(["remap", "in", "--to", "mitsuba06:ward", "-o", "out"], tmp))
    missing = [n for n in ("summary.csv", "summary.json", "index.html") if not (tmp / "out" / n).is_file()]
    return f"no {', '.join(missing)} ({outcome})" if missing else outcome


def batch_long_name(tmp: Path) -> str:
    """A 300-character material name: 'File name too long', no item record, retried by every rerun."""
    batch_gltf(tmp / "in", ["x" * 300, "short"])
    args = ["remap", "in", "--to", "mitsuba06:ward", "-o", "out"]
    p = batch_run(args, tmp)
    if not isinstance(p, str) and "File name too long" in p.stdout + p.stderr:
        return "File name too long"
    if (first := batch_done(p)) != "handled":
        return first
    return batch_done(batch_run(args, tmp), unchanged=2)


def batch_into_its_input(tmp: Path) -> str:
    """``remap in -o in/out`` three times: its own outputs were converted on every rerun (1, 3, 7 materials)."""
    batch_gltf(tmp / "in", ["red"])
    batch_gltf(tmp / "in" / "b", ["dark"])
    counts = []
    for _ in range(3):
        p = batch_run(["remap", "in", "--to", "gltf:metal-rough", "-o", "in/out", "--json"], tmp)
        if isinstance(p, str) or p.returncode not in (0, 3):
            return batch_done(p)
        counts.append(len(json.loads(p.stdout)["items"]))
    return "handled" if counts == [2, 2, 2] else f"CONVERTS ITS OUTPUTS ({', '.join(map(str, counts))} materials)"


def batch_refused_out(tmp: Path, args: list[str], watched: Path) -> str:
    """``refused`` when a batch exits 2 with one line and leaves ``watched`` as it was."""

    def state() -> dict[str, bytes | None]:
        return {str(p): p.read_bytes() if p.is_file() else None for p in sorted(watched.rglob("*"))}

    before = state()
    p = batch_run(args, tmp)
    if isinstance(p, str):
        return p
    if "Traceback" in p.stderr:
        return "TRACEBACK"
    changed = state() != before
    if p.returncode == 2 and p.stderr.count("\n") == 1 and not changed:
        return "refused"
    return f"exit {p.returncode}" + (" (WROTE INTO IT)" if changed else "")


def batch_out_holds_input(tmp: Path) -> str:
    (tmp / "in" / "sub").mkdir(parents=True)
    (tmp / "in" / "a.xml").write_text(BATCH_SCENE)
    (tmp / "in" / "sub" / "b.xml").write_text(BATCH_SCENE)
    return batch_refused_out(
        tmp, ["remap", "in/a.xml", "in/sub/b.xml", "--to", "mitsuba06:ward", "-o", "in"], tmp / "in"
    )


def batch_out_holds_texture(tmp: Path) -> str:
    (tmp / "in" / "tex").mkdir(parents=True)
    png(tmp / "in" / "tex" / "base.png", gradient())
    batch_gltf(tmp / "in", ["a", "b"], ("tex/base.png",))
    return batch_refused_out(tmp, ["remap", "in/m.gltf", "--to", "mitsuba06:ward", "-o", "in/tex"], tmp / "in")


def batch_out_is_cache(tmp: Path) -> str:
    (tmp / "in").mkdir()
    (tmp / "in" / "a.xml").write_text(BATCH_SCENE)
    (tmp / "cache").mkdir()
    (tmp / "cache" / "table.npz").write_bytes(b"cached")
    return batch_refused_out(tmp, ["remap", "in", "--to", "mitsuba06:ward", "-o", "cache"], tmp / "cache")


def batch_out_users_summary(tmp: Path) -> str:
    (tmp / "in").mkdir()
    (tmp / "in" / "a.xml").write_text(BATCH_SCENE)
    (tmp / "out").mkdir()
    (tmp / "out" / "summary.csv").write_text("the user's own table\n")
    return batch_refused_out(tmp, ["remap", "in", "--to", "mitsuba06:ward", "-o", "out"], tmp / "out")


def batch_out_users_slot(tmp: Path) -> str:
    (tmp / "in").mkdir()
    (tmp / "in" / "a.xml").write_text(BATCH_SCENE)
    (tmp / "out" / "a.xml" / "000-wall").mkdir(parents=True)
    (tmp / "out" / "a.xml" / "000-wall" / "notes.txt").write_text("mine\n")
    return batch_refused_out(tmp, ["remap", "in", "--to", "mitsuba06:ward", "-o", "out"], tmp / "out")


def two_batches_one_out(tmp: Path) -> str:
    """Two batches started at once into one OUT: both converted everything (no lock)."""
    for i in range(2):
        (tmp / "in" / f"s{i}").mkdir(parents=True)
        (tmp / "in" / f"s{i}" / "scene.xml").write_text(BATCH_SCENE)
    args = ["remap", "in", "--to", "mitsuba06:ward", "-o", "out", "--workers", "1", *FAST]
    procs = [
        subprocess.Popen(
            [sys.executable, "-m", MODULE, *spelled(args)],
            cwd=tmp,
            env={**os.environ, "MATREMAP_CACHE": str(tmp / f"cache{i}")},
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
        )
        for i in range(2)
    ]
    errs = [proc.communicate(timeout=600)[1] for proc in procs]
    if any("Traceback" in e for e in errs):
        return "TRACEBACK"
    if any(proc.returncode != 0 for proc in procs):
        return "exit " + ", ".join(str(proc.returncode) for proc in procs)
    done = [int(m.group(1)) for e in errs if (m := re.search(r"unchanged, (\d+) to do", e))]
    return "handled" if sum(done) == 4 else f"REDONE ({sum(done)} conversions of 4 materials)"


def batch_children(pid: int) -> set[int]:
    found = set()
    for stat_file in Path("/proc").glob("[0-9]*/stat"):
        try:
            text = stat_file.read_text()
        except OSError:
            continue
        if int(text[text.rfind(")") + 2 :].split()[1]) == pid:
            found.add(int(stat_file.parent.name))
    return found


def batch_alive(pids: set[int]) -> set[int]:
    alive = set()
    for pid in pids:
        try:
            if Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0] != "Z":
                alive.add(pid)
        except OSError:
            continue
    return alive


def batch_stopped(tmp: Path, sig: int) -> str:
    """A batch of textured materials stopped by ``sig`` while items are being converted; then the same command:
    ``handled`` when no worker outlived it by 10 s, the rerun exits 0 and no marked name is left in OUT."""
    for i in range(4):
        shutil.copytree(ROOT / "examples" / "brass-gltf", tmp / "in" / f"brass{i}")
    args = ["remap", "in", "--to", "mitsuba06:ward", "-o", "out", "--workers", "2", *FAST]
    env = {**os.environ, "MATREMAP_CACHE": str(tmp / "cache")}
    proc = subprocess.Popen(
        [sys.executable, "-m", MODULE, *spelled(args)],
        cwd=tmp,
        env=env,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
        start_new_session=True,
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL),  # a background shell ignores SIGINT
    )
    deadline = time.time() + 240
    while proc.poll() is None and time.time() < deadline and not list((tmp / "out").glob("*/.matremap-*")):
        time.sleep(0.02)
    workers = batch_children(proc.pid)
    if proc.poll() is not None:
        return "finished before the signal"
    os.killpg(proc.pid, sig) if sig == signal.SIGINT else proc.send_signal(sig)
    proc.wait(timeout=120)
    deadline = time.time() + 10
    while batch_alive(workers) and time.time() < deadline:
        time.sleep(0.1)
    orphans = batch_alive(workers)
    for pid in orphans:
        os.kill(pid, signal.SIGKILL)
    left = sorted({p.name.split("-")[1] for p in (tmp / "out").rglob(".matremap-*")})
    again = batch_run(args[: -len(FAST)], tmp)
    if orphans:
        return f"ORPHANS ({len(orphans)} worker(s) outlived the batch)"
    if sig == signal.SIGINT and left:
        return f"LEFTOVER after SIGINT (.matremap-{left[0]}-...)"
    if isinstance(again, str) or again.returncode != 0:
        return "rerun " + batch_done(again)
    if list((tmp / "out").rglob(".matremap-*")):
        return "LEFTOVER after the rerun"
    return "handled"


def batch_killed(tmp: Path) -> str:
    return batch_stopped(tmp, signal.SIGKILL)


def batch_terminated(tmp: Path) -> str:
    return batch_stopped(tmp, signal.SIGTERM)


def batch_sigint(tmp: Path) -> str:
    return batch_stopped(tmp, signal.SIGINT)


CASES: list[tuple[str, str, Callable[[Path], str]]] = [
    ("glTF image uri, absolute path elsewhere", "1 confinement", gltf_absolute_uri),
    ("glTF image uri ../", "1 confinement", gltf_parent_uri),
    ("glTF image symlink pointing out", "1 confinement", gltf_symlink_out),
    ("Mitsuba bitmap outside the scene folder", "1 confinement", mitsuba_bitmap_outside),
    ("MaterialX file input ../", "1 confinement", materialx_file_outside),
    ("--write ../../x.gltf", "1 outputs under -o", write_outside),
    ("refusal the same whether the file exists", "1 confinement", same_line_either_way),
    ("glTF buffer uri ../ (image in it)", "1 confinement", gltf_buffer_outside),
    ("glTF copy: another material's image ../", "1 confinement", gltf_copy_names_outside),
    ("Mitsuba <include> ../", "1 confinement", mitsuba_include_outside),
    ("MaterialX xi:include ../", "1 confinement", materialx_xinclude),
    ("MaterialX fileprefix ../", "1 confinement", materialx_fileprefix),
    ("USD texture asset ../", "1 confinement", usd_texture_outside),
    ("USD value clip ../", "1 confinement", usd_value_clip_outside),
    ("USD copy to .usdz: other texture ../", "1 confinement", usd_copy_other_texture_outside),
    (".usdz layer naming ../../ outside", "1 confinement", usdz_member_outside),
    ("map set manifest naming ../", "1 confinement", map_set_manifest_outside),
    ("glb image cache: forged file, manifest", "2 caches", glb_cache_forged),
    ("cached transform edited", "2 caches", cached_transform_edited),
    ("cached table with a byte flipped", "2 caches", cached_table_damaged),
    ("cached sweep database, a page damaged", "2 caches", cached_sweep_damaged),
    ("sweep resumed: a failed point refitted", "3 failed fits", failed_points_refitted),
    ("PNG header claiming 40000 x 40000", "4 memory", absurd_png_header),
    ("transform coef as strings", "5 transforms", transform_string_coef),
    ("transform wrong coefficient count", "5 transforms", transform_coef_count),
    ("transform constant 1e300", "5 transforms", transform_huge_constant),
    ("transform unknown target option", "5 transforms", transform_unknown_option),
    ("transform JSON nested 100k deep", "6 tracebacks", transform_deep),
    ("GLB byteOffset as a string", "6 tracebacks", glb_string_offset),
    ("material JSON nested 100k deep", "6 tracebacks", material_json_deep),
    ("map set manifest nested 100k deep", "6 tracebacks", manifest_deep),
    ("sweep database: bad JSON in a row", "6 tracebacks", sweep_db_bad_json),
    ("sweep database: a dropped column", "6 tracebacks", sweep_db_dropped_column),
    ("two sweeps start one new database", "8 leftovers", two_sweeps_new_db),
    ("glTF data URI with bad base64", "6 tracebacks", data_uri_bad_base64),
    ("GLB chunk length wrapping negative", "6 tracebacks", glb_negative_length),
    ("glTF JSON nested 100k deep", "6 tracebacks", gltf_deep_json),
    ("Mitsuba XML entity expansion", "7 XML", mitsuba_billion_laughs),
    ("Mitsuba XML external entity", "7 XML", mitsuba_external_entity),
    ("transform with NaN coefficients", "5 transforms", transform_with_nan),
    ("inline material JSON > 255 chars", "6 tracebacks", inline_material_long),
    ("sweep database with text for numbers", "6 tracebacks", sweep_db_text_numbers),
    ("RGB base colour, metallic 1, uniform roughness", "7 crash", rgb_base_metal_uniform_rough),
    ("glTF base colour texture of one colour", "7 crash", uniform_texture),
    ("convert killed (SIGKILL), then rerun", "8 leftovers", convert_killed_leftovers),
    ("convert killed (SIGKILL) mid-write, then rerun", "8 leftovers", convert_killed_mid_write),
    ("convert interrupted (SIGINT), then rerun", "8 leftovers", convert_sigint),
    ("remap MAPS killed (SIGKILL) mid-write, rerun", "8 leftovers", remap_maps_killed),
    ("remap MAPS interrupted (SIGINT), then rerun", "8 leftovers", remap_maps_sigint),
    ("remap FILE killed (SIGKILL) mid-write, rerun", "8 leftovers", remap_file_killed),
    ("sweep killed (SIGKILL), then rerun", "8 leftovers", sweep_killed),
    ("sweep interrupted (SIGINT), then rerun", "8 leftovers", sweep_sigint),
    # second round (2026-11-28), one block per class: outputs and --force
    ("remap FILE -o PROJECT --force (input inside)", "R2.1 data loss", force_above_input),
    ("remap FILE -o TEXTURE-FOLDER --force", "R2.1 data loss", force_on_texture_folder),
    ("remap MAPS -o PROJECT --force (maps inside)", "R2.1 data loss", force_above_map_set),
    ("remap -o USER-FOLDER --force (not matremap's)", "R2.1 data loss", force_on_users_folder),
    ("remap -o CACHE --force", "R2.1 data loss", force_on_cache),
    ("remap MAPS --sweep interrupted (SIGINT), rerun", "R2.2 cache poisoned", remap_sweep_sigint),
    ("two remaps sharing a cache, the same sweep", "R2.9 coordination", two_remaps_one_cache),
    #
    #
    # second round: interruption, caches, orphans and leftovers
    #
    #
    # second round: a batch's change detection, its own folders, concurrent runs
    ("batch killed (SIGKILL): workers, rerun", "3 orphans", batch_killed),
    ("batch terminated (SIGTERM): workers, rerun", "3 orphans", batch_terminated),
    ("batch interrupted (SIGINT): leftovers, rerun", "3 leftovers", batch_sigint),
    ("batch: a FIFO named by the material", "4 change detection", batch_fifo),
    ("batch: a link to /dev/zero named by it", "4 change detection", batch_dev_zero),
    ("batch: a link out of the folder, edited", "4 change detection", batch_link_outside),
    ("batch: a file name that is not UTF-8", "7 names", batch_non_utf8_name),
    ("batch: a material name with a bad \\u escape", "7 names", batch_invalid_escape),
    ("batch: a 300-character material name, rerun", "8 own folders", batch_long_name),
    ("batch into its own input folder, 3 runs", "8 own folders", batch_into_its_input),
    ("batch: OUT holds an input", "data loss", batch_out_holds_input),
    ("batch: OUT holds a texture an input names", "data loss", batch_out_holds_texture),
    ("batch: OUT is the cache folder", "data loss", batch_out_is_cache),
    ("batch: OUT holds the user's summary.csv", "data loss", batch_out_users_summary),
    ("batch: OUT holds a folder named like an item", "data loss", batch_out_users_slot),
    ("two batches into one OUT at once", "9 concurrent runs", two_batches_one_out),
    #
    #
    # second round: memory per reader
    *importlib.import_module("memory").HOSTILE_CASES,  # benchmarks/memory.py: each reader's peak, measured
    #
    #
    # second round: expansion bounds, clean lines instead of exit 70, messages
    ("Mitsuba <default> doubling 29 deep", "6 expansion", mitsuba_default_bomb),
    ("Mitsuba <include> fan-out 8 x 7", "6 expansion", mitsuba_include_fan_out),
    ("MaterialX chain of 200 nodes", "7 exit 70", mtlx_chain_200),
    ("MaterialX chain of 5000 nodes", "7 exit 70", mtlx_chain_5000),
    ("asset folder name with a non-UTF-8 byte", "7 exit 70", non_utf8_folder),
    ("-o name with a non-UTF-8 byte", "7 exit 70", non_utf8_output),
    ("disk full (ENOSPC) writing an image", "7 exit 70", disk_full),
    ("SQLite 'database or disk is full'", "7 exit 70", sqlite_full),
    ("error quoting a 1 MB value", "7 messages", mtlx_huge_value),
    ("read-only OUT parent", "9 messages", read_only_out_parent),
    ("MaterialX starting with a UTF-8 BOM", "9 messages", mtlx_utf8_bom),
    ("MaterialX in UTF-16", "9 messages", mtlx_utf16),
    ("FIFO given as a texture", "9 messages", fifo_texture),
    ("--write a/b/c.gltf", "9 messages", mtlx_write_subfolder),
]


def main() -> None:
    verbose = "-v" in sys.argv
    only = [a for a in sys.argv[1:] if a != "-v"]  # parts of case names: run the cases whose name has one
    print(f"{'case':<48} {'finding':<20} outcome")
    for name, finding, fn in CASES:
        if only and not any(w in name for w in only):
            continue
        with tempfile.TemporaryDirectory() as t:
            try:
                outcome = fn(Path(t))
            except Exception as e:  # noqa: BLE001 - the harness reports, it does not stop
                outcome = f"harness error: {type(e).__name__}: {e}"
        print(f"{name:<48} {finding:<20} {outcome}" + (f"  | {LAST[0][:150]}" if verbose else ""), flush=True)
        LAST[0] = ""


if __name__ == "__main__":
    main()
