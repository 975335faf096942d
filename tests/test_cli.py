import json
import os
import subprocess
import sys

import numpy as np
import pytest

from matremap.cli import main
from matremap.core.material import Material
from matremap.core.scene import Scene
from matremap.renderers import get_renderer

WARD = (
    '{"model": "mitsuba06:ward", "params": '
    '{"variant": "ward", "specularReflectance": 0.12, "alpha": 0.3, "diffuseReflectance": 0}}'
)


def run(capsys, *argv):
    code = main(list(argv))
    out, err = capsys.readouterr()
    return code, out, err


def test_models_json_lists_parameters_bounds_and_options(capsys):
    code, out, _ = run(capsys, "models", "--json")
    assert code == 0
    models = {m["id"]: m for m in json.loads(out)}
    ward = models["mitsuba06:ward"]
    assert {p["name"] for p in ward["params"]} == {"alpha", "specularReflectance", "diffuseReflectance"}
    assert ward["options"][0]["choices"] == ["ward", "ward-duer", "balanced"]
    assert all("bounds" in p and "role" in p for m in models.values() for p in m["params"])


def test_models_shows_one_model(capsys):
    code, out, _ = run(capsys, "models", "mitsuba06:roughconductor")
    assert code == 0 and "distribution: beckmann | ggx | phong | as" in out


@pytest.mark.parametrize("suffix", [".npy", ".exr", ".png"])
def test_render_writes_the_image(capsys, tmp_path, suffix):
    out = tmp_path / f"sphere{suffix}"
    code, _, _ = run(capsys, "render", WARD, "-o", str(out), "--size", "32")
    assert code == 0 and out.is_file()
    expected = get_renderer().render([Material.from_dict(json.loads(WARD))], Scene(resolution=32))[0]
    if suffix == ".npy":
        np.testing.assert_array_equal(np.load(out), expected)
    elif suffix == ".exr":
        from matremap.svbrdf.textures import read_image

        np.testing.assert_array_equal(read_image(out, "linear")[0], expected)
    else:
        from matremap.svbrdf.textures import read_image

        assert read_image(out)[0].shape == (32, 32, 3)


def test_render_refuses_to_overwrite_without_force(capsys, tmp_path):
    out = tmp_path / "keep.npy"
    out.write_bytes(b"precious")
    code, _, err = run(capsys, "render", WARD, "-o", str(out))
    assert code == 2 and "--force" in err and out.read_bytes() == b"precious"
    code, _, _ = run(capsys, "render", WARD, "-o", str(out), "--force", "--size", "16")
    assert code == 0 and np.load(out).shape == (16, 16, 3)


def test_fit_json_prints_one_object(capsys, tmp_path):
    out = tmp_path / "fit.json"
    code, stdout, _ = run(
        capsys,
        "fit",
        "--source",
        WARD,
        "--to",
        "mitsuba06:pbr",
        "--fix",
        "distribution=as",
        "--json",
        "-o",
        str(out),
    )
    assert code == 0
    record = json.loads(stdout)
    assert {"params", "loss", "renders", "seconds", "strategy"} <= set(record)
    assert record["params"]["distribution"] == "as"
    # the authors' table gives alpha2 = 0.26784 at alpha1 = 0.2947 and 0.28923 at 0.3237: 0.2717 at 0.3
    assert record["params"]["alpha"] == pytest.approx(0.2717, rel=5e-3)
    assert json.loads(out.read_text())["params"] == record["params"]


def test_fit_reads_a_material_file_and_prints_a_table(capsys, tmp_path):
    f = tmp_path / "ward.json"
    f.write_text(WARD)
    code, out, _ = run(
        capsys,
        "fit",
        "--source",
        str(f),
        "--to",
        "cycles:glossy",
        "--light",
        "0",
        "45",
        "--size",
        "64",
        "--strategy",
        "three-stage",
    )
    assert code == 0 and "Roughness =" in out and "stage joint" in out


@pytest.mark.parametrize(
    "argv, message",
    [
        (["fit", "--source", WARD, "--to", "mitsuba06:wart"], "unknown model 'mitsuba06:wart'; did you mean"),
        (["fit", "--source", WARD, "--to", "mitsuba06:pbr", "--fix", "shine=1"], "has no parameter 'shine'"),
        (["fit", "--source", WARD, "--to", "mitsuba06:pbr", "--fix", "distribution=cook"], "not one of"),
        (["fit", "--source", "mitsuba06:ward,alpha=nan", "--to", "mitsuba06:pbr"], "not finite"),
        (["fit", "--source", "mitsuba06:ward,alpha=7", "--to", "mitsuba06:pbr"], "outside its range"),
        (["fit", "--source", "mitsuba06:ward,diffuseReflectance=1:2", "--to", "mitsuba06:pbr"], "RGB triple"),
        (["fit", "--source", "missing.json", "--to", "mitsuba06:pbr"], "not found"),
        (["fit", "--source", WARD, "--to", "mitsuba06:pbr", "--light", "east"], "--light takes an angle"),
        (["render", WARD, "-o", "x.jpg2"], "unknown file type"),
    ],
)
def test_bad_input_is_one_line_exit_2(capsys, tmp_path, argv, message):
    os.chdir(tmp_path)
    code, out, err = run(capsys, *argv)
    assert code == 2
    assert message in err and err.count("\n") == 1 and err.startswith("matremap: error:")
    assert list(tmp_path.iterdir()) == []


def test_malformed_material_file(capsys, tmp_path):
    f = tmp_path / "bad.json"
    f.write_text('{"model": "mitsuba06:ward", "params": {"alpha": 0.1,}')
    out = tmp_path / "fit.json"
    code, _, err = run(capsys, "fit", "--source", str(f), "--to", "mitsuba06:pbr", "-o", str(out))
    assert code == 2 and "not valid JSON" in err and not out.exists()


def test_console_script_runs():
    proc = subprocess.run([sys.executable, "-m", "matremap.cli", "models"], capture_output=True, text=True)
    assert proc.returncode == 0 and "mitsuba06:ward" in proc.stdout
    proc = subprocess.run([sys.executable, "-m", "matremap.cli", "fit"], capture_output=True, text=True)
    assert proc.returncode == 2 and "required" in proc.stderr


def test_fit_compare_writes_source_target_difference(capsys, tmp_path):
    from matremap.svbrdf.textures import read_image

    out = tmp_path / "cmp.exr"
    code, stdout, _ = run(
        capsys, "fit", "--source", WARD, "--to", "cycles:glossy", "--size", "48", "--compare", str(out), "--json"
    )
    assert code == 0
    loss = json.loads(stdout)["loss"]
    strip, _ = read_image(out, "linear")
    assert strip.shape == (48, 3 * 48 + 8, 3)
    source, target, diff = strip[:, :48], strip[:, 52:100], strip[:, 104:]
    assert np.linalg.norm(target - source) / np.linalg.norm(source) == pytest.approx(loss, rel=1e-3)
    np.testing.assert_allclose(diff, 10 * np.abs(target - source), rtol=1e-4, atol=1e-6)

    png = tmp_path / "cmp.png"  # a picture to look at: a caption band names the panels
    assert run(capsys, "fit", "--source", WARD, "--to", "cycles:glossy", "--size", "48", "--compare", str(png))[0] == 0
    labelled, _ = read_image(png, "srgb")
    assert labelled.shape[0] > 48 and labelled.shape[1] == 3 * 48 + 8
    band = labelled[: labelled.shape[0] - 48]
    assert band.max() > 0.5 and np.median(band) < 0.1  # white text on a dark band


def test_renderers_lists_the_backends_and_their_models(capsys):
    code, out, _ = run(capsys, "renderers", "--json")
    assert code == 0
    rows = {r["name"]: r for r in json.loads(out)}
    assert rows["embedded"]["available"] and "mitsuba06:ward" in rows["embedded"]["models"]
    assert "mitsuba3" in rows  # listed whether or not Mitsuba 3 is installed
    if rows["mitsuba3"]["available"]:
        assert "mitsuba3:roughconductor" in rows["mitsuba3"]["models"]
    else:
        assert "pip install" in rows["mitsuba3"]["reason"]


def test_every_command_group_is_assembled_in_the_listed_order(capsys):
    import argparse

    import matremap.cli as cli

    assert sorted(cli.COMMANDS) == sorted(cli.PARSERS)

    class Recorder:
        names: list[str] = []

        def add_parser(self, name, **kwargs):
            self.names.append(name)
            return argparse.ArgumentParser(prog=name)

    for name, add in cli.PARSERS.items():
        add(Recorder())
        assert Recorder.names[-1] == name  # each adder adds the command it is listed under
    with pytest.raises(SystemExit):
        main(["--help"])
    listed = capsys.readouterr().out.split("{", 1)[1].split("}", 1)[0].split(",")
    assert listed == list(cli.COMMANDS)


def test_choices_come_from_the_fit_strategies_and_the_learner_table():
    from matremap.cli import build_parser
    from matremap.core.fit import STRATEGIES
    from matremap.regress.learners import LEARNERS

    parser = build_parser()
    fit = parser.parse_args(["fit", "--source", WARD, "--to", "mitsuba06:pbr"])
    assert fit.strategy == "two-stage" and fit.source_renderer is None and fit.target_renderer is None
    with pytest.raises(SystemExit):
        parser.parse_args(["fit", "--source", WARD, "--to", "mitsuba06:pbr", "--strategy", "four-stage"])
    for strategy in STRATEGIES:
        assert parser.parse_args(["remap", "m", "--to", "x", "-o", "o", "--strategy", strategy]).strategy == strategy
    for method in LEARNERS:
        assert parser.parse_args(["learn", "db", "-o", "t.json", "--method", method]).method == method


def test_fit_and_sweep_draw_a_model_with_its_own_renderer_by_default(capsys, tmp_path):
    from matremap.errors import MatremapError
    from matremap.sweep.store import SweepStore

    try:
        get_renderer("mitsuba3")
    except MatremapError as e:
        pytest.skip(str(e))
    # Mitsuba 3's rough plastic has no emulation (its conductor has): Mitsuba 3 draws it
    source = "mitsuba3:roughplastic,alpha=0.2,int_ior=1.5"
    code, out, _ = run(capsys, "fit", "--source", source, "--to", "gltf:metal-rough", "--size", "32", "--json")
    assert code == 0 and json.loads(out)["renderers"] == {"source": "mitsuba3", "target": "embedded"}
    db = tmp_path / "m.sqlite"
    argv = ["sweep", "--source", source, "--to", "gltf:metal-rough", "--fix", "metallic=0"]
    argv += ["--grid", "alpha=0.1:0.2:2", "--db", str(db), "--workers", "1", "--no-progress", "--size", "32"]
    assert run(capsys, *argv)[0] == 0
    with SweepStore.open(db) as store:  # the database names the renderers, as before
        assert store.config["renderers"] == {"source": "mitsuba3", "target": "embedded"}
        assert len(store.rows("ok")) == 2


# -- a CLI that explains itself (issue 20, must-have 4) ---------------------------------------------


def _commands():
    """(name, parser) of every command."""
    import argparse

    from matremap.cli import build_parser

    sub = next(a for a in build_parser()._actions if isinstance(a, argparse._SubParsersAction))
    return list(sub.choices.items())


def _visible(action):
    """The spellings of an option ``--help`` shows (not the old ones of a renamed option)."""
    return [o for o in action.option_strings if o not in getattr(action, "old", ())]


def test_every_option_says_what_it_does_and_its_default():
    import argparse

    missing, no_default = [], []
    for name, parser in _commands():
        for action in parser._actions:
            if isinstance(action, argparse._HelpAction) or action.help == argparse.SUPPRESS:
                continue
            where = f"{name} {'/'.join(action.option_strings) or action.dest}"
            if not (action.help or "").strip():
                missing.append(where)
                continue
            default = action.default
            if default not in (None, False, [], argparse.SUPPRESS):
                shown = action.help % {"default": default, "prog": name, "dest": action.dest}
                if f"default {default}" not in shown and f"default: {default}" not in shown:
                    no_default.append(f"{where} (default {default!r})")
    assert not missing, f"options without help text: {missing}"
    assert not no_default, f"options whose help does not give the default: {no_default}"


def test_every_command_has_a_description_and_examples_that_parse():
    import re
    import shlex

    from matremap.cli import build_parser

    parser = build_parser()
    for name, sub in _commands():
        assert sub.description and sub.epilog and sub.epilog.startswith("examples:"), name
        text = sub.epilog.replace("\\\n", " ")
        # a command line, maybe after environment variables; up to a pipe or a comment in parentheses
        found = [re.match(r"\s*(?:\w+=\S+\s+)*(matremap .*)", line) for line in text.splitlines()]
        examples = [m.group(1).split(" | ")[0].split("  (")[0].strip() for m in found if m]
        assert any(e.split()[1] == name for e in examples), f"{name}: no example of the command itself"
        for example in examples:
            argv = shlex.split(example)[1:]
            try:
                parser.parse_args(argv)
            except SystemExit:
                pytest.fail(f"{name}'s example does not parse: {example}")


#: names that mean the same thing: two of a group offered by the CLI would be two names for one concept
SYNONYMS = [
    {"light", "lights", "probe-light", "light-angle"},
    {"size", "resolution", "res", "image-size"},
    {"to", "target", "target-model-id"},
    {"from", "model", "source-model-id"},
    {"workers", "jobs", "processes", "procs", "cores"},
    {"output", "out", "output-dir"},
    {"force", "overwrite"},
    {"envmap", "environment", "env", "hdri"},
    {"env-lights", "env-samples", "samples"},
]


def test_one_name_per_concept():
    import argparse

    spellings: dict[str, set[str]] = {}  # option -> the dests it stores into, over all commands
    for name, parser in _commands():
        for action in parser._actions:
            if isinstance(action, argparse._HelpAction) or action.help == argparse.SUPPRESS:
                continue
            longs = [o for o in _visible(action) if o.startswith("--")]
            assert len(longs) <= 1, f"{name}: one option shown under several names {longs}"
            for o in longs:
                spellings.setdefault(o[2:], set()).add(action.dest)
    # the same spelling means the same thing everywhere
    assert all(len(d) == 1 for d in spellings.values()), {o: d for o, d in spellings.items() if len(d) > 1}
    # no two spellings that differ by a plural or a separator (--light / --lights)
    norm: dict[str, list[str]] = {}
    for o in spellings:
        norm.setdefault(o.replace("-", "").replace("_", "").rstrip("s"), []).append(o)
    assert all(len(v) == 1 for v in norm.values()), [v for v in norm.values() if len(v) > 1]
    for group in SYNONYMS:
        offered = sorted(group & set(spellings))
        assert len(offered) <= 1, f"two names for one concept: {offered}"


def test_old_spellings_work_for_a_release_with_a_note(capsys):
    from matremap.cli import build_parser
    from matremap.cli.common import OLD_NAMES_REMOVED_IN

    parser = build_parser()
    args = parser.parse_args(["evaluate", "a", "b", "-o", "o", "--lights", "32"])
    err = capsys.readouterr().err
    assert args.env_lights == 32
    assert (
        err.strip() == f"matremap: note: --lights is deprecated (removed in {OLD_NAMES_REMOVED_IN}); use --env-lights"
    )
    assert parser.parse_args(["fit", "--source", WARD, "--target", "cycles:glossy"]).target == "cycles:glossy"
    assert parser.parse_args(["convert", "m", "--model", "mitsuba06:ward", "-o", "o"]).source == "mitsuba06:ward"
    err = capsys.readouterr().err
    assert "--target is deprecated" in err and "use --to" in err and "use --from" in err
    assert parser.parse_args(["fit", "--source", WARD, "--to", "cycles:glossy"]).target == "cycles:glossy"
    assert capsys.readouterr().err == ""  # the current spelling says nothing
    with pytest.raises(SystemExit):
        main(["evaluate", "--help"])
    shown = capsys.readouterr().out
    assert "--env-lights N" in shown and "--lights" not in shown


def test_size_sets_the_evaluation_renders_of_remap(capsys, tmp_path):
    from matremap.svbrdf.textures import read_image

    examples = os.path.join(os.path.dirname(__file__), "..", "examples", "bronze")
    for size in (24, 40):
        out = tmp_path / f"s{size}"
        argv = ["remap", examples, "--to", "mitsuba06:ward", "-o", str(out), "--rotations", "0"]
        code, _, err = run(capsys, *argv, "--size", str(size), "--env-lights", "16")
        assert code == 0, err
        image, _ = read_image(out / "report" / "images" / "r000_full_target.png")
        assert image.shape[:2] == (size, size)


# -- a map set converts to a material file (issue 20) -----------------------------------------------


def test_a_map_set_remap_writes_a_gltf_that_uses_the_converted_maps(capsys, tmp_path):
    pygltflib = pytest.importorskip("pygltflib", reason="pip install pygltflib")
    from matremap.svbrdf.textures import read_image

    bronze = os.path.join(os.path.dirname(__file__), "..", "examples", "bronze")
    out = tmp_path / "out"
    argv = ["remap", bronze, "--to", "gltf:metal-rough", "-o", str(out), "--no-evaluate", "--cache", str(tmp_path)]
    code, stdout, err = run(capsys, *argv, "--write", "bronze.gltf")
    assert code == 0, err
    assert f"{out / 'bronze.gltf'}" in stdout
    gltf = pygltflib.GLTF2().load(str(out / "bronze.gltf"))
    (material,) = gltf.materials
    manifest = json.loads((out / "maps" / "material.json").read_text())
    assert manifest["model"] == "gltf:metal-rough"

    def texture(index):
        uri = gltf.images[gltf.textures[index].source].uri
        assert (out / uri).is_file() and "/" not in uri  # beside the file, inside OUT
        return out / uri

    pbr = material.pbrMetallicRoughness
    base, _ = read_image(texture(pbr.baseColorTexture.index), "srgb")
    converted, _ = read_image(out / "maps" / manifest["maps"]["baseColor"], "srgb")
    np.testing.assert_allclose(base[..., :3], converted[..., :3], atol=1 / 255)
    mr, _ = read_image(texture(pbr.metallicRoughnessTexture.index), "linear")
    rough, _ = read_image(out / "maps" / manifest["maps"]["roughness"], "linear")
    np.testing.assert_allclose(mr[..., 1], rough[..., 0], atol=1 / 255)  # glTF 2.0 §3.9.2: roughness in G
    assert pbr.metallicFactor == manifest["params"]["metallic"] == 0.0
    assert material.extensions["KHR_materials_ior"]["ior"] == pytest.approx(manifest["params"]["ior"])
    assert material.normalTexture is not None


@pytest.mark.parametrize(
    "name, message",
    [
        ("bronze.xml", "a mitsuba-xml file holds mitsuba3:* materials, not gltf:metal-rough; write a .gltf or .glb"),
        ("maps/bronze.gltf", "OUT/maps/ holds the remap's own files"),
        ("../bronze.gltf", "points outside the output folder"),
    ],
)
def test_a_material_file_the_target_cannot_be_written_as_is_refused_before_any_work(capsys, tmp_path, name, message):
    bronze = os.path.join(os.path.dirname(__file__), "..", "examples", "bronze")
    out = tmp_path / "out"
    code, _, err = run(capsys, "remap", bronze, "--to", "gltf:metal-rough", "-o", str(out), "--write", name)
    assert code == 2 and message in err and err.count("\n") == 1
    assert not out.exists()
