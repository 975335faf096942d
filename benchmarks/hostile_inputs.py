"""What matremap does with hostile and malformed inputs (issue 19's probe), one row per case.

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
    python benchmarks/hostile_inputs.py killed     # the cases whose name has "killed"

The interruption cases run the command once uninterrupted, then again with a signal sent when a staging
folder appears (or a file in it has bytes, "mid-write"; for a sweep, when a point is in the database),
then a third time, the same command without ``--force``: ``handled`` when the third run exits 0, leaves no
hidden file behind and writes what the uninterrupted run wrote (and, for SIGINT, the interrupted run
exited 130 with ``matremap: interrupted`` last and no traceback).

Run it on two checkouts to compare (the issue's "probe, before, after" table).
"""

from __future__ import annotations

import json
import os
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


def cli(args: list[str], cwd: Path, timeout: float = 300) -> subprocess.CompletedProcess[str]:
    env = {**os.environ, "MATREMAP_CACHE_DIR": str(cwd / "cache"), "MATREMAP_CACHE": str(cwd / "cache")}
    return subprocess.run(
        [sys.executable, "-m", "matremap", *args], cwd=cwd, env=env, capture_output=True, text=True, timeout=timeout
    )


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


def transform_with_nan(tmp: Path) -> str:
    doc = json.loads((ROOT / "src" / "matremap" / "regress" / "transforms" / "ward-as.json").read_text())
    doc["mappings"]["roughness"]["coef"] = [float("nan")] * len(doc["mappings"]["roughness"]["coef"])
    (tmp / "t.json").write_text(json.dumps(doc))  # json writes NaN, which Python's reader accepts
    p = cli(["convert", str(ROOT / "examples" / "bronze"), "--transform", "t.json", "-o", "out"], tmp)
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
    """Hidden files and folders (staging, temporary files) anywhere under ``tmp``, the cache aside."""
    return [f for f in tmp.rglob(".*") if "cache" not in f.relative_to(tmp).parts]


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
            [sys.executable, "-m", "matremap", *args],
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


CASES: list[tuple[str, str, Callable[[Path], str]]] = [
    ("glTF image uri, absolute path elsewhere", "1 confinement", gltf_absolute_uri),
    ("glTF image uri ../", "1 confinement", gltf_parent_uri),
    ("glTF image symlink pointing out", "1 confinement", gltf_symlink_out),
    ("Mitsuba bitmap outside the scene folder", "1 confinement", mitsuba_bitmap_outside),
    ("MaterialX file input ../", "1 confinement", materialx_file_outside),
    ("--write ../../x.gltf", "1 outputs under -o", write_outside),
    ("glTF data URI with bad base64", "6 tracebacks", data_uri_bad_base64),
    ("GLB chunk length wrapping negative", "6 tracebacks", glb_negative_length),
    ("glTF JSON nested 100k deep", "6 tracebacks", gltf_deep_json),
    ("Mitsuba XML entity expansion", "7 XML", mitsuba_billion_laughs),
    ("Mitsuba XML external entity", "7 XML", mitsuba_external_entity),
    ("transform with NaN coefficients", "5 transforms", transform_with_nan),
    ("inline material JSON > 255 chars", "6 tracebacks", inline_material_long),
    ("sweep database with text for numbers", "6 tracebacks", sweep_db_text_numbers),
    ("RGB base colour, metallic 1, uniform roughness", "7 crash", rgb_base_metal_uniform_rough),
    ("convert killed (SIGKILL), then rerun", "8 leftovers", convert_killed_leftovers),
    ("convert killed (SIGKILL) mid-write, then rerun", "8 leftovers", convert_killed_mid_write),
    ("convert interrupted (SIGINT), then rerun", "8 leftovers", convert_sigint),
    ("remap MAPS killed (SIGKILL) mid-write, rerun", "8 leftovers", remap_maps_killed),
    ("remap MAPS interrupted (SIGINT), then rerun", "8 leftovers", remap_maps_sigint),
    ("remap FILE killed (SIGKILL) mid-write, rerun", "8 leftovers", remap_file_killed),
    ("sweep killed (SIGKILL), then rerun", "8 leftovers", sweep_killed),
    ("sweep interrupted (SIGINT), then rerun", "8 leftovers", sweep_sigint),
]


def main() -> None:
    only = sys.argv[1:]  # words a case's name must contain (e.g. "killed"), to run a few
    print(f"{'case':<48} {'finding':<20} outcome")
    for name, finding, fn in CASES:
        if only and not all(w in name for w in only):
            continue
        with tempfile.TemporaryDirectory() as t:
            try:
                outcome = fn(Path(t))
            except Exception as e:  # noqa: BLE001 - the harness reports, it does not stop
                outcome = f"harness error: {type(e).__name__}: {e}"
        print(f"{name:<48} {finding:<20} {outcome}")


if __name__ == "__main__":
    main()
