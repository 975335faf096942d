"""What the format modules share: parsing untrusted XML, picking a material of a file, and writing a
document's maps beside it.

The XML readers (Mitsuba, and MaterialX before its own parser sees the file) parse with
:func:`parse_untrusted_xml`: defusedxml refuses entity declarations (so no entity expansion and no
external entity is ever resolved, whatever the expat version) and the parse stops past
:data:`MAX_XML_DEPTH` nested elements.

Writers of documents that reference their maps (Mitsuba 3 XML, MaterialX) take a result apart with
:func:`result_parts`, refuse existing map files up front with :func:`check_map_destinations`, and
put every map beside the document with :func:`place_map`, inside the document's
:class:`~matremap.core.atomic.AtomicFiles` group, so the document and its maps appear together.
"""

from __future__ import annotations

import re
import xml.etree.ElementTree as ET
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np

from matremap.core.atomic import FORCE_HINT, AtomicFiles
from matremap.core.material import Material
from matremap.dialects import get_model
from matremap.errors import MatremapError

#: the suffixes :func:`place_map` may give a map
MAP_SUFFIXES = (".png", ".exr")
#: the deepest element nesting an XML material file may have (scenes and documents nest a few levels)
MAX_XML_DEPTH = 100


def parse_untrusted_xml(path: Path, expected: str, data: bytes | None = None) -> ET.Element:
    """The root element of XML file ``path`` (or of its bytes ``data``), parsed safely: entity
    declarations (entity expansion, external entities) are refused and nesting stops at
    :data:`MAX_XML_DEPTH`. ``expected`` says what the file should be, in errors."""
    import io

    import defusedxml  # type: ignore[import-untyped]
    import defusedxml.ElementTree as DET  # type: ignore[import-untyped]

    depth = 0
    try:
        source = io.BytesIO(data if data is not None else path.read_bytes())
        events = DET.iterparse(source, events=("start", "end"), forbid_dtd=False, forbid_entities=True)
        for event, _ in events:
            depth += 1 if event == "start" else -1
            if depth > MAX_XML_DEPTH:
                raise MatremapError(
                    f"{path} nests elements deeper than {MAX_XML_DEPTH} levels; give {expected} "
                    f"(a real one nests a few levels)"
                )
        root = events.root  # set once the parse is complete
    except defusedxml.DefusedXmlException as e:
        raise MatremapError(
            f"{path}: the XML declares entities or external references ({type(e).__name__}), which matremap "
            f"refuses (entity expansion and external entities can exhaust memory or read other files); "
            f"give {expected} without a DTD"
        ) from None
    except ET.ParseError as e:
        raise MatremapError(f"{path} is not valid XML ({e}); give {expected}") from None
    except MatremapError:
        raise
    except (LookupError, ValueError) as e:  # expat: an encoding Python does not know, or a multi-byte one
        raise MatremapError(
            f"{path}: its XML declaration names an encoding matremap cannot read ({e}); save it as UTF-8"
        ) from None
    except OSError as e:
        raise MatremapError(f"cannot read {path}: {e}") from None
    return root


def pick_material(path: Path, names: list[str], material: str | int | None, noun: str = "material") -> int:
    """The index of the material a reader was asked for: the first for None, an index (negative
    counts from the end) or a name from ``names``. ``noun`` is what the format calls them (in errors)."""
    if material is None:
        return 0
    if isinstance(material, int) and not isinstance(material, bool):
        if not -len(names) <= material < len(names):
            raise MatremapError(f"{path} has {len(names)} {noun}(s); material index {material} is out of range")
        return material % len(names)
    if isinstance(material, str) and material in names:
        return names.index(material)
    raise MatremapError(f"{path} has no {noun} named {material!r}; its {noun}s are {', '.join(map(repr, names))}")


class ResultParts(NamedTuple):
    """A result to write, taken apart: the uniform material (its values stand for untextured
    parameters), the map files by parameter, their colour spaces ("srgb"/"linear"), the normal map."""

    material: Material
    maps: dict[str, Path]
    colorspace: dict[str, str]
    normal: Path | None


def result_parts(result: Any, writer: str, models: tuple[str, ...]) -> ResultParts:
    """Take a Material or MapSet apart for ``writer`` (named in errors), which writes ``models``;
    map files must exist. A map's colour space is the map set's, else what its file suggests."""
    from matremap.svbrdf.textures import MapSet

    if isinstance(result, Material):
        if result.model not in models:
            raise MatremapError(
                f"{writer} writes {', '.join(models)} materials, not {result.model}; remap to one of these first"
            )
        return ResultParts(result, {}, {}, None)
    if not isinstance(result, MapSet):
        raise MatremapError(f"{writer} writes a Material or a MapSet, not {type(result).__name__}")
    spec = get_model(result.model)
    if spec.id not in models:
        raise MatremapError(
            f"{writer} writes {', '.join(models)} materials, not {spec.id}; remap to one of these first"
        )
    m = Material.create(spec.id, {k: v for k, v in result.constants.items() if k not in result.maps})
    for name, f in result.maps.items():
        spec.param(name)
        if not Path(f).is_file():
            raise MatremapError(f"map {f} for {name} not found")
    if result.normal is not None and not Path(result.normal).is_file():
        raise MatremapError(f"normal map {result.normal} not found")
    colorspace = {
        name: result.colorspace.get(name) or default_colorspace(Path(f), spec.param(name).channels == 3)
        for name, f in result.maps.items()
    }
    maps = {k: Path(v) for k, v in result.maps.items()}
    return ResultParts(m, maps, colorspace, Path(result.normal) if result.normal else None)


def default_colorspace(path: Path, colour: bool) -> str:
    """The colour space matremap assumes for a map file that does not say (sRGB for 8/16-bit colour)."""
    from matremap.svbrdf.textures import image_info

    return image_info(path, colour=colour).colorspace


def map_destination(out: Path, name: str) -> Path:
    """Where the map of parameter ``name`` goes beside document ``out``, without its suffix:
    ``<stem>_<name>`` (characters other than letters, digits, ``_.-`` replaced by ``_``)."""
    return out.parent / f"{out.stem}_{re.sub(r'[^A-Za-z0-9_.-]', '_', name)}"


def check_map_destinations(out: Path, names: list[str], force: bool) -> None:
    """Refuse, before any work, to write maps ``names`` beside ``out`` over existing files (either
    suffix a map may get) unless ``force``."""
    if force:
        return
    for name in names:
        stem = map_destination(out, name)
        for suffix in MAP_SUFFIXES:
            if stem.with_suffix(suffix).exists():
                raise MatremapError(f"{stem.with_suffix(suffix)} already exists; {FORCE_HINT}")


def place_map(
    src: Path, dest_stem: Path, keep: bool, colorspace: str, channels: int | None, files: AtomicFiles
) -> Path:
    """Stage map ``src`` in ``files`` as ``dest_stem`` + suffix: copied as it is when ``keep`` (and it
    is a PNG or EXR with the right channel count; a file already at its destination stays), else
    converted to a linear float EXR (decoded with ``colorspace``; ``channels`` 1 keeps the first
    channel, 3 makes grey RGB). Returns the destination."""
    from matremap.svbrdf.textures import image_info, transform_image

    info = image_info(src, colorspace)
    if keep and info.format in ("png", "exr") and (channels is None or info.channels == channels):
        dest = dest_stem.with_suffix("." + info.format)
        if dest.resolve() != src.resolve():
            files.copy(src, dest)
        return dest

    def picked(band: np.ndarray) -> np.ndarray:
        if channels == 1:
            return band[..., :1]
        if channels == 3:
            return np.repeat(band, 3, axis=-1) if band.shape[-1] == 1 else band[..., :3]
        return band

    dest = dest_stem.with_suffix(".exr")
    transform_image(src, colorspace, files.stage(dest), picked)  # band by band: any map size
    return dest


__all__ = [
    "MAP_SUFFIXES",
    "MAX_XML_DEPTH",
    "ResultParts",
    "check_map_destinations",
    "default_colorspace",
    "map_destination",
    "parse_untrusted_xml",
    "pick_material",
    "place_map",
]
