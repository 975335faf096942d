"""A copy of a Mitsuba 3 scene (and of the files it includes) in which BSDFs are replaced.

Source: Mitsuba 3.9 ``src/core/parser.cpp`` (how includes and file names resolve: see
:mod:`matremap.formats.mitsuba_scene`). The copy is made from each file as written -- ``<default>`` and
``$name`` kept -- and then:

* every ``<string name="filename">`` and ``<spectrum filename>`` is rewritten to the file it names in the
  source (found as Mitsuba finds it, confined), relative to the new main scene's folder, which is where
  Mitsuba resolves plugin file names of every file of the scene;
* every ``<include>`` is rewritten to the copy of the included file: the main scene goes to ``out``, an
  included file to ``<out stem>_include/<its path under the source scene's folder>`` (or
  ``<out stem>_include/outside/<n>_<name>`` for one from an ``--allow-path`` folder);
* ``<path>`` elements are dropped: no file name needs them any more;
* :meth:`SceneCopy.replace` puts a new BSDF where a named one was, keeping its ``id`` and ``name``
  attributes (so ``<ref>``s bind to it) and the source's ``twosided`` / ``mask`` wrappers around it.
"""

from __future__ import annotations

import copy
import os
import xml.etree.ElementTree as ET
from pathlib import Path

from matremap.errors import MatremapError
from matremap.formats.mitsuba_bsdfs import BsdfReader
from matremap.formats.mitsuba_plugins import WRAPPERS
from matremap.formats.mitsuba_scene import ORIGIN, MitsubaScene, load_scene, strip_origin


class SceneCopy:
    """The files of scene ``source`` copied for writing as ``out`` (module doc)."""

    def __init__(self, source: Path, out: Path) -> None:
        self.scene: MitsubaScene = load_scene(source)
        self.out = out
        self.bsdfs = dict(BsdfReader(self.scene).candidates())
        self.targets: dict[Path, Path] = {}  # source file -> its copy
        self.trees: dict[Path, ET.Element] = {}
        self.by_origin: dict[str, ET.Element] = {}
        self.parents: dict[ET.Element, ET.Element] = {}
        for index, f in enumerate(self.scene.files):
            if f.path in self.trees:
                continue
            self.targets[f.path] = out if index == 0 else self._include_target(f.path, index)
            tree = copy.deepcopy(f.raw)
            self.trees[f.path] = tree
            for el in tree.iter():
                self.by_origin.setdefault(el.get(ORIGIN, ""), el)
                for child in el:
                    self.parents[child] = el
        for f in self.scene.files:
            self._rebase(f.path)

    def _include_target(self, path: Path, index: int) -> Path:
        folder = self.out.parent / f"{self.out.stem}_include"
        if path.is_relative_to(self.scene.folder):
            return folder / path.relative_to(self.scene.folder)
        return folder / "outside" / f"{index}_{path.name}"

    def _rebase(self, path: Path) -> None:
        """Rewrite file names and includes of the copy of ``path``; drop its ``<path>`` elements."""
        tree = self.trees[path]
        index = next(i for i, f in enumerate(self.scene.files) if f.path == path)
        includes = self.scene.files[index].includes
        here = self.targets[path].parent
        for el in list(tree.iter()):
            origin = el.get(ORIGIN, "")
            merged = self.scene.merged(origin)
            if el.tag == "include":
                serial = int(origin.split(":")[1])
                target = self.targets.get(self.scene.files[includes[serial]].path) if serial in includes else None
                if target is not None:
                    el.set("filename", _relative(target, here))
            elif el.tag == "path":
                self.parents[el].remove(el)
            elif merged is not None and el.tag == "string" and el.get("name") == "filename":
                el.set("value", self._rebased(merged.get("value", ""), "file name"))
            elif merged is not None and el.tag == "spectrum" and merged.get("filename"):
                el.set("filename", self._rebased(merged.get("filename", ""), "spectrum file"))

    def _rebased(self, name: str, what: str) -> str:
        found = self.scene.resolve(name, f"{self.scene.path}: {what}", must_exist=False)
        return _relative(found, self.out.parent)

    def replace(self, name: str, bsdf: ET.Element) -> None:
        """Put ``bsdf`` where the BSDF named ``name`` was (module doc)."""
        merged = self.bsdfs.get(name)
        if merged is None:
            raise MatremapError(f"{self.scene.path} has no BSDF named {name!r}; its BSDFs are {', '.join(self.bsdfs)}")
        old = self.by_origin.get(merged.get(ORIGIN, ""))
        if old is None or old not in self.parents:
            raise MatremapError(f"{self.scene.path}: BSDF {name!r} cannot be replaced in the copy")
        new = bsdf
        for wrapper in reversed(self._wrappers(merged)):
            outer = ET.Element("bsdf", {"type": wrapper.get("type", "")})
            for child in wrapper:  # the wrapper's own properties (a mask's opacity), as copied and rebased
                if child.tag != "bsdf" and child.tag != "ref":
                    outer.append(copy.deepcopy(self.by_origin.get(child.get(ORIGIN, ""), child)))
            outer.append(new)
            new = outer
        for key in ("id", "name"):
            if old.get(key) is not None:
                new.set(key, old.get(key, ""))
        parent = self.parents[old]
        parent[list(parent).index(old)] = new
        self.parents[new] = parent

    def _wrappers(self, el: ET.Element) -> list[ET.Element]:
        """The source's twosided and mask wrappers around the core of ``el``, outermost first (normal
        perturbations are the converted material's own)."""
        kept: list[ET.Element] = []
        while el.get("type") in WRAPPERS:
            if el.get("type") in ("twosided", "mask"):
                kept.append(el)
            inner = [c for c in el if c.tag in ("bsdf", "ref")]
            if not inner:
                break
            el = self.scene.ids.get(inner[0].get("id", ""), inner[0]) if inner[0].tag == "ref" else inner[0]
        return kept

    def documents(self) -> list[tuple[Path, str]]:
        """(destination, text) of every file of the copy."""
        out = []
        for path, tree in self.trees.items():
            root = strip_origin(copy.deepcopy(tree))
            ET.indent(root, space="    ")
            text = ET.tostring(root, encoding="unicode")
            comment = f"<!-- copied by matremap from {path.name}: BSDFs converted, file names rebased -->\n"
            out.append((self.targets[path], '<?xml version="1.0" encoding="utf-8"?>\n' + comment + text + "\n"))
        return out


def _relative(target: Path, folder: Path) -> str:
    try:
        return os.path.relpath(target, folder).replace(os.sep, "/")
    except ValueError:  # another drive
        return str(target)


__all__ = ["SceneCopy"]
