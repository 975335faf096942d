"""A Mitsuba 3 scene file as Mitsuba's parser sees it: includes, search paths, defaults, ids.

Source: Mitsuba 3.9 ``src/core/parser.cpp`` (``parse_xml_node``: the ``<include>``, ``<path>`` and
``<default>`` cases, ``substitute_parameters``, ``max_include_depth`` = 15 in ``parser.h``) and
``src/core/python/parser.cpp`` (``load_file`` puts the scene's folder first on the file resolver),
checked against Mitsuba 3.9.1 (tests/test_mitsuba_scene.py).

* ``<include filename="...">`` is looked up in the including file's folder first, then on the file
  resolver; a scene-rooted file's children take the include's place, any other root element (a
  ``<bsdf>``) is placed as it is. Nesting deeper than :data:`MAX_INCLUDE_DEPTH` and cycles are refused.
* ``<path value="...">`` (a child of the root) puts a folder first on the resolver: relative to the
  file that names it, else looked up on the resolver. Plugins resolve their file names (bitmaps) on
  the *main* file's resolver once the whole scene is parsed -- its folder and its ``<path>``s, not
  the folder of an included file (a ``<path>`` inside an included file serves that file's includes).
* ``<default name value>`` defines ``$name`` for what follows, in document order and across includes;
  the first definition wins. Substitution replaces the longest names first; a ``$`` left over is an
  undefined parameter; ``\\$`` is a literal dollar.
* ids are one namespace across all files; a duplicate is an error, as in Mitsuba.

Expansion is bounded as XML parsers bound entity expansion: the ``$name`` substitutions of a scene may
produce at most :data:`MAX_EXPANDED` characters in all (a ``<default>`` whose value repeats an earlier
one twice doubles at each level), a scene may follow at most :data:`MAX_INCLUDES` ``<include>`` elements
(counting each one: a fan-out of files each including the next several times multiplies) and parse at
most :data:`MAX_SCENE_BYTES` bytes of XML across its files. Past a bound the scene is refused in one line
naming it, before the work it would cost.

Every file, include and search folder must lie in the main scene's folder or a folder the user
allowed (:mod:`matremap.formats.confine`). :class:`MitsubaScene` keeps each file's tree as written
(for writers that copy the scene) and the merged, substituted tree readers work on; both carry the
attribute :data:`ORIGIN` (file index and element number) so an element of one is found in the other.
"""

from __future__ import annotations

import re
import xml.etree.ElementTree as ET
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

from matremap.errors import MatremapError, not_a_file, shorten
from matremap.formats.common import parse_untrusted_xml
from matremap.formats.confine import Confinement, resolve_reference

#: Mitsuba 3's ``ParserConfig::max_include_depth``
MAX_INCLUDE_DEPTH = 15
#: the most characters the ``$name`` substitutions of one scene may produce, all values together (a real
#: scene's produce a few hundred)
MAX_EXPANDED = 1 << 24
#: the most ``<include>`` elements one scene may follow, each counted (a real scene follows a few)
MAX_INCLUDES = 1000
#: the most bytes of XML one scene may parse, its own and its included files' together
MAX_SCENE_BYTES = 1 << 28
#: attribute matremap adds to every element: "<file index>:<element number in that file>"
ORIGIN = "{matremap}origin"
#: tags whose ``id`` Mitsuba registers (objects)
_OBJECTS = (
    "bsdf",
    "texture",
    "shape",
    "emitter",
    "sensor",
    "film",
    "sampler",
    "rfilter",
    "integrator",
    "medium",
    "phase",
    "volume",
    "spectrum",
)


@dataclass
class SceneFile:
    """One XML file of a scene: its path (resolved), its tree as written (elements tagged with
    :data:`ORIGIN`) and whether it is a Mitsuba 0.6 file (version below 2: camelCase names)."""

    path: Path
    raw: ET.Element
    legacy: bool
    #: element number of an <include> in this file -> index of the file it included
    includes: dict[int, int] = field(default_factory=dict)


@dataclass
class MitsubaScene:
    """A scene loaded as Mitsuba loads it (see the module doc)."""

    path: Path
    confinement: Confinement | None
    files: list[SceneFile] = field(default_factory=list)
    root: ET.Element = field(default_factory=lambda: ET.Element("scene"))
    ids: dict[str, ET.Element] = field(default_factory=dict)
    #: the main file's resolver: its <path> folders (last declared first), then its own folder
    search: list[Path] = field(default_factory=list)
    _defaults: dict[str, str] = field(default_factory=dict)
    _by_origin: dict[str, ET.Element] = field(default_factory=dict)
    #: the defaults' names, longest first (the order substitution tries them in); None when one was added
    _order: list[str] | None = None
    #: characters produced by substitution so far, <include>s followed, bytes of XML parsed
    _expanded: int = 0
    _included: int = 0
    _parsed: int = 0

    @property
    def folder(self) -> Path:
        return self.path.resolve().parent

    def fail(self, el: ET.Element | None, msg: str) -> MatremapError:
        where = self.file_of(el).path if el is not None else self.path
        return MatremapError(f"{where}: {msg}")

    def file_of(self, el: ET.Element) -> SceneFile:
        """The file element ``el`` (of either tree) was written in."""
        origin = el.get(ORIGIN)
        return self.files[int(origin.split(":")[0])] if origin else self.files[0]

    def merged(self, origin: str) -> ET.Element | None:
        """The merged element of origin ``origin`` (None for one that is not in the merged tree)."""
        return self._by_origin.get(origin)

    def resolve(self, name: str, what: str, must_exist: bool = True) -> Path:
        """The file a plugin's file name ``name`` names, as Mitsuba's resolver finds it: the first of the
        search folders holding it (all confined). ``what`` names the reference in errors."""
        found = self.first(name, self.search, what, Path.is_file)
        if found is None and must_exist:
            special = self.first(name, self.search, what, Path.exists)
            if special is not None:
                raise MatremapError(f"{what} {shorten(name)!r}: {not_a_file(special, 'the file')}")
            where = ", ".join(str(f) for f in self.search)
            raise MatremapError(f"{what} {name!r} not found in {where}; put it there or fix its file name")
        return found or self.confine(name, self.search[-1], what)

    def first(self, ref: str, folders: list[Path], what: str, test: Callable[[Path], bool]) -> Path | None:
        """The first of ``folders`` / ``ref`` that passes ``test`` (exists), trying them in order as Mitsuba's
        resolver does; each is confined before it is looked at."""
        for folder in folders:
            candidate = self.confine(ref, folder, what)
            if test(candidate):
                return candidate
        return None

    def confine(self, ref: str, base: Path, what: str) -> Path:
        """``ref`` resolved against folder ``base``, refused (naming ``ref`` as written, whether or not the
        file exists) unless it lies in the scene's folder or an allowed one (:func:`resolve_reference`)."""
        joined = ref if Path(ref).is_absolute() else str(base / ref)
        try:
            return resolve_reference(joined, self.folder, what, self.confinement)
        except MatremapError:
            raise MatremapError(
                f"{what} {ref!r} points outside the asset folder {self.folder}; pass --allow-path DIR to allow it"
            ) from None

    # -- loading ---------------------------------------------------------------------------------
    def load(self) -> MitsubaScene:
        p = self.path
        if not p.is_file():
            raise MatremapError(not_a_file(p, "Mitsuba scene"))
        self.search = [self.folder]
        raw = self._parse(p, 0)
        if raw.tag not in ("scene", "bsdf"):
            raise MatremapError(f"{p} is not a Mitsuba scene: its root element is <{raw.tag}>, not <scene> or <bsdf>")
        self.root = self._copy(raw, 0)
        self._children(raw, self.root, 0, self.search, (p.resolve(),))
        return self

    def _parse(self, path: Path, depth: int) -> ET.Element:
        """Parse file ``path`` as file number ``len(self.files)`` and tag its elements."""
        try:
            data = path.read_bytes()
        except OSError as e:
            raise MatremapError(f"cannot read {path}: {e.strerror or e}") from None
        self._parsed += len(data)
        if self._parsed > MAX_SCENE_BYTES:
            raise self.fail(
                None,
                f"the scene and its included files hold more than {MAX_SCENE_BYTES:,} bytes of XML; matremap stops "
                "there (a real scene is far smaller: are files included many times over?)",
            )
        root = parse_untrusted_xml(path, "a Mitsuba 3 scene file", data)
        index = len(self.files)
        for serial, el in enumerate(root.iter()):
            el.set(ORIGIN, f"{index}:{serial}")
        version = root.get("version")
        legacy = False
        if version is not None:
            try:
                legacy = int(version.split(".")[0]) < 2
            except ValueError:
                raise MatremapError(f"{path}: version {version!r} is not a version number like 3.0.0") from None
        self.files.append(SceneFile(path.resolve(), root, legacy))
        return root

    def _copy(self, el: ET.Element, file_index: int) -> ET.Element:
        """The merged element for raw ``el``: its attributes with ``$name`` substituted."""
        attrs = {k: (self._substitute(el, v) if "$" in v else v) for k, v in el.attrib.items()}
        out = ET.Element(el.tag, attrs)
        self._by_origin[attrs[ORIGIN]] = out
        object_id = attrs.get("id")
        if object_id is not None and el.tag in _OBJECTS:
            if object_id in self.ids:
                raise self.fail(el, f"id {object_id!r} is defined twice (ids are one namespace across included files)")
            self.ids[object_id] = out
        return out

    def _substitute(self, el: ET.Element, value: str) -> str:
        """``value`` with ``$name`` replaced as Mitsuba does (longest names first, ``\\$`` kept), refused
        once the scene's substitutions would produce more than :data:`MAX_EXPANDED` characters."""
        if self._order is None:
            self._order = sorted(self._defaults, key=len, reverse=True)
        for key in self._order:
            if "$" + key not in value:
                continue
            replacement = self._defaults[key]
            pattern = re.compile(r"(?<!\\)\$" + re.escape(key))
            count = sum(1 for _ in pattern.finditer(value))
            if self._expanded + len(value) + count * (len(replacement) - len(key) - 1) > MAX_EXPANDED:
                raise self.fail(
                    el,
                    f"substituting ${shorten(key)} would expand the scene's parameters past {MAX_EXPANDED:,} "
                    "characters (a <default> repeating another grows exponentially); matremap stops there",
                )
            value = pattern.sub(replacement.replace("\\", "\\\\"), value)  # a literal in the template
        self._expanded += len(value)
        left = re.search(r"(?<!\\)\$(\w*)", value)
        if left:
            name = shorten(left.group(1))
            raise self.fail(
                el, f'${name} is used but no <default name="{name}" value=...> before it gives it a value; add one'
            )
        return value.replace("\\$", "$")

    def _children(
        self, raw: ET.Element, out: ET.Element, file_index: int, resolver: list[Path], chain: tuple[Path, ...]
    ) -> None:
        """Merge the children of raw element ``raw`` (of file ``file_index``) into ``out``."""
        for child in raw:
            if not isinstance(child.tag, str):
                continue
            if child.tag == "default":
                self._default(child)
            elif child.tag == "include":
                self._include(child, out, file_index, resolver, chain)
            elif child.tag == "path":
                if raw is not self.files[file_index].raw:
                    raise self.fail(child, "<path> can only be a child of the root element (as in Mitsuba)")
                resolver.insert(0, self._search_folder(child, file_index, resolver))
            else:
                merged = self._copy(child, file_index)
                out.append(merged)
                self._children(child, merged, file_index, resolver, chain)

    def _default(self, el: ET.Element) -> None:
        name, value = el.get("name"), el.get("value")
        if not name or value is None:
            raise self.fail(el, "a <default> needs a name and a value attribute")
        if "$" in value:
            value = self._substitute(el, value)
        if name not in self._defaults:  # the first definition wins, as in Mitsuba
            self._defaults[name] = value
            self._order = None

    def _search_folder(self, el: ET.Element, file_index: int, resolver: list[Path]) -> Path:
        value = el.get("value")
        if not value:
            raise self.fail(el, "<path> needs a value attribute (a folder)")
        value = self._substitute(el, value) if "$" in value else value
        what = f"{self.files[file_index].path}: <path>"
        if Path(value).is_absolute():
            folder = self.confine(value, self.folder, what)
        else:
            here = self.files[file_index].path.parent
            folder = self.first(value, [here, *resolver], what, Path.is_dir) or self.confine(value, here, what)
        if not folder.is_dir():
            raise self.fail(el, f"<path> folder {value!r} not found (looked in {self.files[file_index].path.parent})")
        return folder

    def _include(
        self, el: ET.Element, out: ET.Element, file_index: int, resolver: list[Path], chain: tuple[Path, ...]
    ) -> None:
        name = el.get("filename")
        if not name:
            raise self.fail(el, "<include> needs a filename attribute")
        name = self._substitute(el, name) if "$" in name else name
        here = self.files[file_index].path.parent
        inner = [here, *resolver]  # Mitsuba clones the resolver and puts the including file's folder first
        what = f"{self.files[file_index].path}: <include>"
        target = self.first(name, inner, what, Path.is_file)
        special = self.first(name, inner, what, Path.exists) if target is None else None
        if special is not None:
            raise self.fail(el, f"included file {shorten(name)!r}: {not_a_file(special, 'the file')}")
        if target is None:
            raise self.fail(el, f"included file {name!r} not found (looked in {here}); fix its filename")
        if target in chain:
            cycle = " -> ".join(p.name for p in (*chain, target))
            raise self.fail(el, f"<include> cycle ({cycle}); a file cannot include itself")
        if len(chain) > MAX_INCLUDE_DEPTH - 1:
            raise self.fail(el, f"includes nest deeper than {MAX_INCLUDE_DEPTH} files (Mitsuba's limit)")
        self._included += 1
        if self._included > MAX_INCLUDES:
            raise self.fail(
                el,
                f"the scene follows more than {MAX_INCLUDES} <include>s (each counted; files including others several "
                "times multiply); matremap stops there",
            )
        index = len(self.files)
        self.files[file_index].includes[int(el.get(ORIGIN, "0:0").split(":")[1])] = index
        raw = self._parse(target, len(chain))
        if raw.tag == "scene":
            self._children(raw, out, index, inner, (*chain, target))
            return
        merged = self._copy(raw, index)
        merged.attrib.pop("version", None)
        if el.get("name") is not None:
            merged.set("name", el.get("name", ""))
        out.append(merged)
        self._children(raw, merged, index, inner, (*chain, target))


def load_scene(path: str | Path, confinement: Confinement | None = None) -> MitsubaScene:
    """The scene of Mitsuba XML file ``path`` with its includes, defaults, search paths and ids."""
    return MitsubaScene(Path(path), confinement).load()


def strip_origin(el: ET.Element) -> ET.Element:
    """``el`` (in place) without the :data:`ORIGIN` attributes matremap added."""
    for e in el.iter():
        e.attrib.pop(ORIGIN, None)
    return el


__all__ = [
    "MAX_EXPANDED",
    "MAX_INCLUDES",
    "MAX_INCLUDE_DEPTH",
    "MAX_SCENE_BYTES",
    "ORIGIN",
    "MitsubaScene",
    "SceneFile",
    "load_scene",
    "strip_origin",
]
