"""Mitsuba 3 scene structure as Mitsuba's parser reads it: <include> (relative to the including file,
recursive, cycles and depth refused), <path> search folders, <default>/$name across includes (first
definition wins, only after it is defined), ids and <ref>s across files, every BSDF listed -- all confined
to the scene's folder unless allowed. Where Mitsuba 3 is installed the same scenes are loaded by it and
must agree (which file is found, which value a default gives, which scenes fail)."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import numpy as np
import pytest

from matremap.errors import MatremapError
from matremap.formats import Confinement, material_names, read_asset
from matremap.formats.mitsuba_scene import MAX_INCLUDE_DEPTH, load_scene
from matremap.svbrdf.textures import ImageInfo, write_image_like

needs_mitsuba = pytest.mark.skipif(
    importlib.util.find_spec("mitsuba") is None, reason="Mitsuba 3 not installed: pip install 'matremap[mitsuba]'"
)


def xml(path: Path, body: str, root: str = "scene") -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(f'<{root} version="3.0.0">\n{body}\n</{root.split()[0]}>\n')
    return path


def exr(path: Path, value: float) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    return write_image_like(
        path, np.full((4, 4, 3), value, np.float32), ImageInfo("exr", "float", 3, 0, 0, "linear"), force=True
    )


def mitsuba_reflectances(path: Path) -> dict[str, list[float]]:
    """``<bsdf id>.reflectance.value`` of every diffuse BSDF Mitsuba 3 loads from ``path``."""
    import mitsuba as mi

    mi.set_variant("scalar_rgb")
    params = mi.traverse(mi.load_file(str(path), optimize=False))  # no merging of equal BSDFs
    return {
        k.split(".")[0]: [float(x) for x in np.asarray(params[k]).reshape(-1)]
        for k in params.keys()
        if k.endswith("reflectance.value")
    }


def include_scene(tmp_path: Path) -> Path:
    """main.xml includes parts/materials.xml (which includes ../common/base.xml); a <path> folder holds a
    bitmap; defaults are set in main and in the includes; a shape in main refers to a BSDF of an include."""
    exr(tmp_path / "textures" / "wood.exr", 0.25)
    xml(
        tmp_path / "common" / "base.xml",
        """<default name="grey" value="0.9"/><default name="tint" value="0.1, 0.2, 0.3"/>
        <bsdf type="diffuse" id="base"><rgb name="reflectance" value="$grey"/></bsdf>""",
    )
    xml(
        tmp_path / "parts" / "materials.xml",
        """<include filename="../common/base.xml"/>
        <bsdf type="diffuse" id="painted"><rgb name="reflectance" value="$tint"/></bsdf>
        <bsdf type="diffuse" id="wood"><texture type="bitmap" name="reflectance">
            <string name="filename" value="wood.exr"/></texture></bsdf>""",
    )
    return xml(
        tmp_path / "main.xml",
        """<default name="grey" value="0.5"/>
        <path value="textures"/>
        <include filename="parts/materials.xml"/>
        <bsdf type="diffuse" id="late"><rgb name="reflectance" value="$tint"/></bsdf>
        <shape type="sphere" id="ball"><ref id="painted"/></shape>
        <shape type="sphere"><ref id="base"/></shape><shape type="sphere"><ref id="late"/></shape>
        <shape type="sphere" id="floor"><bsdf type="diffuse"><rgb name="reflectance" value="0.7"/></bsdf></shape>""",
    )


def test_includes_paths_defaults_and_refs_across_files(tmp_path):
    main = include_scene(tmp_path)
    assert material_names(main) == ["base", "painted", "wood", "late", "floor/bsdf"]
    # the first <default> wins: main's grey 0.5, not base.xml's 0.9
    assert read_asset(main, "base").constants == {"reflectance": 0.5}
    # a default set in an included file serves what follows it, in the main file too
    assert read_asset(main, "painted").constants == {"reflectance": [0.1, 0.2, 0.3]}
    assert read_asset(main, "late").constants == {"reflectance": [0.1, 0.2, 0.3]}
    # the bitmap of an included file is found on the main file's resolver: the <path> folder
    wood = read_asset(main, "wood")
    assert wood.textures["reflectance"].path == (tmp_path / "textures" / "wood.exr").resolve()
    scene = load_scene(main)
    assert [f.path.name for f in scene.files] == ["main.xml", "materials.xml", "base.xml"]
    assert scene.search[0] == (tmp_path / "textures").resolve() and scene.search[-1] == tmp_path.resolve()


@needs_mitsuba
def test_mitsuba_reads_the_include_scene_the_same_way(tmp_path):
    main = include_scene(tmp_path)
    got = mitsuba_reflectances(main)
    assert {"base", "painted", "late"} <= set(got) and len(got) == 4  # and the floor's anonymous BSDF
    (floor,) = set(got) - {"base", "painted", "late"}
    for name, key in (("base", "base"), ("painted", "painted"), ("late", "late"), ("floor/bsdf", floor)):
        ours = read_asset(main, name).constants["reflectance"]
        assert np.allclose(got[key], np.broadcast_to(ours, (3,)), atol=1e-6), name


def test_a_bitmap_named_in_an_included_file_is_not_looked_up_beside_it(tmp_path):
    """Mitsuba resolves plugin file names on the main file's resolver; an included file's folder is not on it."""
    exr(tmp_path / "sub" / "tex" / "t.exr", 0.5)
    xml(
        tmp_path / "sub" / "inc.xml",
        '<bsdf type="diffuse" id="d"><texture type="bitmap" name="reflectance">'
        '<string name="filename" value="tex/t.exr"/></texture></bsdf>',
    )
    main = xml(tmp_path / "main.xml", '<include filename="sub/inc.xml"/><shape type="sphere"><ref id="d"/></shape>')
    with pytest.raises(MatremapError, match="bitmap reflectance 'tex/t.exr' not found"):
        read_asset(main)
    if importlib.util.find_spec("mitsuba") is not None:
        with pytest.raises(Exception, match="tex/t.exr"):
            mitsuba_reflectances(main)
    # moved beside the main file, both find it
    exr(tmp_path / "tex" / "t.exr", 0.5)
    assert read_asset(main).textures["reflectance"].path == (tmp_path / "tex" / "t.exr").resolve()


def test_a_bsdf_rooted_include_inside_a_shape(tmp_path):
    xml(
        tmp_path / "gold.xml",
        '<string name="material" value="Au"/><float name="alpha" value="0.2"/>',
        root='bsdf type="roughconductor" id="gold"',
    )
    main = xml(tmp_path / "main.xml", '<shape type="sphere" id="s"><include filename="gold.xml"/></shape>')
    assert material_names(main) == ["gold"]
    assert read_asset(main).constants == {"material": "Au", "alpha": 0.2}


def test_include_cycles_depth_and_missing_files_are_refused(tmp_path):
    a = xml(tmp_path / "a.xml", '<include filename="b.xml"/><bsdf type="diffuse"/>')
    xml(tmp_path / "b.xml", '<include filename="a.xml"/>')
    with pytest.raises(MatremapError, match=r"<include> cycle \(a.xml -> b.xml -> a.xml\)"):
        read_asset(a)
    for i in range(MAX_INCLUDE_DEPTH + 1):
        xml(
            tmp_path / f"d{i}.xml",
            f'<include filename="d{i + 1}.xml"/>' if i < MAX_INCLUDE_DEPTH else "<bsdf type='diffuse'/>",
        )
    with pytest.raises(MatremapError, match=f"deeper than {MAX_INCLUDE_DEPTH} files"):
        read_asset(tmp_path / "d0.xml")
    # one level less loads
    (tmp_path / f"d{MAX_INCLUDE_DEPTH - 1}.xml").write_text('<scene version="3.0.0"><bsdf type="diffuse"/></scene>')
    assert read_asset(tmp_path / "d0.xml").model == "mitsuba3:diffuse"
    gone = xml(tmp_path / "g.xml", '<include filename="nowhere.xml"/>')
    with pytest.raises(MatremapError, match="included file 'nowhere.xml' not found"):
        read_asset(gone)


def test_includes_and_paths_outside_the_scene_folder_are_confined(tmp_path):
    outside = tmp_path / "elsewhere"
    xml(outside / "lib.xml", '<bsdf type="diffuse" id="x"/>')
    exr(outside / "t.exr", 0.5)
    scene_dir = tmp_path / "scene"
    inc = xml(scene_dir / "inc.xml", '<include filename="../elsewhere/lib.xml"/>')
    missing = xml(scene_dir / "missing.xml", '<include filename="../elsewhere/none.xml"/>')
    messages = []
    for p in (inc, missing):
        with pytest.raises(MatremapError, match="points outside the asset folder") as e:
            read_asset(p)
        messages.append(str(e.value).split("'")[1])
    assert messages == ["../elsewhere/lib.xml", "../elsewhere/none.xml"]
    assert read_asset(inc, confinement=Confinement.of([outside])).name == "x"
    path = xml(
        scene_dir / "path.xml",
        '<path value="../elsewhere"/><bsdf type="diffuse"><texture type="bitmap" name="reflectance">'
        '<string name="filename" value="t.exr"/></texture></bsdf>',
    )
    with pytest.raises(MatremapError, match="points outside the asset folder"):
        read_asset(path)
    assert read_asset(path, confinement=Confinement.of([outside])).textures["reflectance"].path == (outside / "t.exr")


def test_path_folders_come_first_like_mitsubas_resolver(tmp_path):
    exr(tmp_path / "t.exr", 0.1)
    exr(tmp_path / "hi" / "t.exr", 0.9)
    p = xml(
        tmp_path / "s.xml",
        '<path value="hi"/><bsdf type="diffuse" id="d"><texture type="bitmap" name="reflectance">'
        '<string name="filename" value="t.exr"/></texture></bsdf><shape type="sphere"><ref id="d"/></shape>',
    )
    assert read_asset(p).textures["reflectance"].path == (tmp_path / "hi" / "t.exr").resolve()
    if importlib.util.find_spec("mitsuba") is not None:
        import mitsuba as mi

        mi.set_variant("scalar_rgb")
        params = mi.traverse(mi.load_file(str(p)))
        assert np.allclose(np.asarray(params["d.reflectance.data"]), 0.9, atol=1e-6)


def test_defaults_follow_document_order_and_escapes(tmp_path):
    late = xml(
        tmp_path / "late.xml",
        '<bsdf type="diffuse"><rgb name="reflectance" value="$g"/></bsdf><default name="g" value="0.3"/>',
    )
    with pytest.raises(MatremapError, match=r"\$g is used but no <default"):
        read_asset(late)
    longest = xml(
        tmp_path / "long.xml",
        '<default name="a" value="0.1"/><default name="ab" value="0.7"/>'
        '<bsdf type="diffuse" id="m"><rgb name="reflectance" value="$ab"/></bsdf>',
    )
    a = read_asset(longest)
    assert a.constants == {"reflectance": 0.7}  # $ab, not $a followed by "b"
    escaped = xml(tmp_path / "esc.xml", '<bsdf type="diffuse" id="cost\\$5"/>')
    assert material_names(escaped) == ["cost$5"]


def test_duplicate_ids_across_files_are_refused(tmp_path):
    xml(tmp_path / "inc.xml", '<bsdf type="diffuse" id="m"/>')
    p = xml(tmp_path / "main.xml", '<bsdf type="diffuse" id="m"/><include filename="inc.xml"/>')
    with pytest.raises(MatremapError, match="id 'm' is defined twice"):
        read_asset(p)
