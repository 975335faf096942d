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
the included file from anywhere), and MaterialX then reads the very bytes that were checked, decoded
as XML 1.0 (Appendix F, "Autodetection of Character Encodings") says: a byte order mark (UTF-8, UTF-16,
UTF-32), else UTF-16 recognised by its zero bytes, else the ``encoding`` of the XML declaration, else
UTF-8. MaterialX is given the text without its declaration (it would read the declared encoding again).
"""

from __future__ import annotations

import codecs
import re
from functools import lru_cache
from pathlib import Path
from typing import Any

from matremap.errors import MatremapError, not_a_file, shorten
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
    if not p.is_file():
        raise MatremapError(not_a_file(p, "MaterialX document"))
    try:
        data = p.read_bytes()
    except OSError as e:
        raise MatremapError(f"cannot read {p}: {e.strerror or e}") from None
    encoding = xml_encoding(data)
    try:
        head = codecs.getincrementaldecoder(encoding)(errors="replace").decode(data[:4096])
    except LookupError:
        raise MatremapError(f"{p}: its XML declaration names the unknown encoding {shorten(encoding)!r}") from None
    if not head.lstrip("\ufeff \t\r\n").startswith("<"):
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
        text = data.decode(encoding)
    except UnicodeDecodeError:
        raise MatremapError(f"{p} is not a MaterialX document: it is not {encoding.upper()} text") from None
    text = _DECLARATION.sub("", text.lstrip("\ufeff"), count=1)
    try:
        m.readFromXmlString(doc, text, m.FileSearchPath(), options)
    except Exception as e:  # noqa: BLE001 - MaterialX raises its own ExceptionParseError and others
        raise MatremapError(f"{p} is not a MaterialX document ({str(e).strip() or type(e).__name__})") from None
    doc.setDataLibrary(library())
    return doc


#: byte order marks (longest first) -> the codec that decodes such a file (its mark dropped)
_BOMS = (
    (codecs.BOM_UTF32_LE, "utf-32"),
    (codecs.BOM_UTF32_BE, "utf-32"),
    (codecs.BOM_UTF8, "utf-8-sig"),
    (codecs.BOM_UTF16_LE, "utf-16"),
    (codecs.BOM_UTF16_BE, "utf-16"),
)
#: an XML declaration at the start of a text, and the encoding one names (in ASCII-compatible bytes)
_DECLARATION = re.compile(r"\A\s*<\?xml\b[^>]*\?>")
_DECLARED = re.compile(rb"\A\s*<\?xml\b[^>]*?\bencoding\s*=\s*[\"']([A-Za-z][A-Za-z0-9._-]*)[\"']")


def xml_encoding(data: bytes) -> str:
    """The codec of an XML document's bytes (XML 1.0 Appendix F): its byte order mark, else UTF-16 told
    by its zero bytes around the first ``<``, else its declaration's ``encoding``, else UTF-8."""
    for bom, codec in _BOMS:
        if data.startswith(bom):
            return codec
    if data[:2] == b"<\x00":
        return "utf-16-le"
    if data[:2] == b"\x00<":
        return "utf-16-be"
    declared = _DECLARED.match(data[:1024])
    if declared is None:
        return "utf-8-sig"
    name = declared.group(1).decode("ascii").lower()
    return "utf-8-sig" if name.replace("-", "").replace("_", "") == "utf8" else name


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
