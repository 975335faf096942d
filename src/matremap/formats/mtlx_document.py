"""MaterialX documents as matremap opens them: untrusted bytes checked, parsed by MaterialX, and
validated against MaterialX's standard data libraries.

Sources: the MaterialX specification v1.39 (https://materialx.org/Specification.html, §"MaterialX
Documents": a document references the node definitions of its data libraries, which are not part of
the file) and the MaterialX Python API 1.39 (``mx.loadLibraries`` with ``mx.getDefaultDataLibraryFolders()``
and ``mx.getDefaultDataSearchPath()`` -- the ``libraries`` folder PyPI's ``materialx`` ships --,
``Document.setDataLibrary``, ``Document.validate``). A document validated without the libraries is
refused whenever it connects to a library node's named output (``gltf_colorimage``'s ``outcolor``),
since the validator cannot see the node's definition; with them, a valid document validates.

The bytes are untrusted: before MaterialX's parser sees them they are parsed with
:func:`~matremap.formats.common.parse_untrusted_xml` (entity declarations and nesting past
:data:`~matremap.formats.common.MAX_XML_DEPTH` refused), ``xi:include`` is refused (MaterialX would read
the included file from anywhere), and MaterialX then reads the very bytes that were checked.
"""

from __future__ import annotations

from functools import lru_cache
from pathlib import Path
from typing import Any

from matremap.errors import MatremapError
from matremap.formats.common import parse_untrusted_xml

FORMAT = "mtlx"
MODEL = "gltf:metal-rough"
INSTALL_HINT = "reading and writing MaterialX needs its Python package: pip install 'matremap[materialx]'"
#: working colour spaces whose colours matremap reads as they are (linear Rec.709 primaries)
WORKING_SPACES = ("", "lin_rec709")

#: per shader: (colour input, weight input) of its emission -- MaterialX's library multiplies the two into
#: a uniform_edf's colour (bxdf/standard_surface.mtlx, open_pbr_surface.mtlx, gltf_pbr.mtlx)
EMISSION = {
    "gltf_pbr": ("emissive", "emissive_strength"),
    "standard_surface": ("emission_color", "emission"),
    "open_pbr_surface": ("emission_color", "emission_luminance"),
}
#: per shader: its opacity input (Standard Surface's is a color3; the others a float)
OPACITY = {"gltf_pbr": "alpha", "standard_surface": "opacity", "open_pbr_surface": "geometry_opacity"}


def mx() -> Any:
    """The MaterialX Python module (an install hint when it is missing)."""
    try:
        import MaterialX
    except ImportError as e:
        raise MatremapError(f"{INSTALL_HINT} ({e})") from None
    return MaterialX


@lru_cache(maxsize=1)
def library() -> Any:
    """MaterialX's standard data libraries (node definitions, their defaults and implementations)."""
    m = mx()
    lib = m.createDocument()
    m.loadLibraries(m.getDefaultDataLibraryFolders(), m.getDefaultDataSearchPath(), lib)
    return lib


def validate(doc: Any) -> tuple[bool, str]:
    """Whether ``doc`` is valid with the standard libraries as its data library, and the first problem."""
    doc.setDataLibrary(library())
    ok, why = doc.validate()
    return bool(ok), "" if ok else (why.strip().splitlines() or ["invalid"])[0]


def parse_document(p: Path) -> Any:
    """The MaterialX document of file ``p`` (its bytes checked as untrusted XML first), with the
    standard libraries as its data library, upgraded to 1.39 by MaterialX's reader."""
    m = mx()
    try:
        data = p.read_bytes()
    except OSError as e:
        raise MatremapError(f"cannot read {p}: {e}") from None
    if not data[:4096].lstrip().startswith(b"<"):
        raise MatremapError(f"{p} is not a MaterialX document (not XML)")
    root = parse_untrusted_xml(p, "a MaterialX document", data)
    if root.tag != "materialx":
        raise MatremapError(f"{p} is not a MaterialX document: its root element is not <materialx>")
    if any(isinstance(el.tag, str) and el.tag.rsplit("}", 1)[-1] == "include" for el in root.iter()):
        raise MatremapError(f"{p}: xi:include is not supported; paste the included document's elements into it")
    doc = m.createDocument()
    options = m.XmlReadOptions()
    options.readXIncludeFunction = None  # refused above already; never let MaterialX follow one
    try:
        m.readFromXmlString(doc, data.decode("utf-8-sig"), m.FileSearchPath(), options)
    except UnicodeDecodeError:
        raise MatremapError(f"{p} is not a MaterialX document: it is not UTF-8 text") from None
    except Exception as e:  # noqa: BLE001 - MaterialX raises its own ExceptionParseError and others
        raise MatremapError(f"{p} is not a MaterialX document ({str(e).strip() or type(e).__name__})") from None
    doc.setDataLibrary(library())
    return doc


def valid_document(p: Path) -> Any:
    """:func:`parse_document`, refused unless it validates with the libraries and its working colour
    space is linear Rec.709 (colours in any other would be misread)."""
    doc = parse_document(p)
    ok, why = validate(doc)
    if not ok:
        raise MatremapError(f"{p} is not a valid MaterialX document: {why}")
    space = (doc.getColorSpace() or "").strip()
    if space not in WORKING_SPACES:
        raise MatremapError(
            f"{p}: the document's colour space is {space!r}; matremap reads documents in lin_rec709 "
            f"(its colours would be misread); convert the document to lin_rec709"
        )
    return doc


__all__ = [
    "EMISSION",
    "FORMAT",
    "INSTALL_HINT",
    "MODEL",
    "OPACITY",
    "WORKING_SPACES",
    "library",
    "mx",
    "parse_document",
    "valid_document",
    "validate",
]
