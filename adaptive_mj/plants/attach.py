"""A payload MJCF attached at a site of an arm MJCF, as one self-contained MJCF text for MuJoCo's
own compiler (no dm_control on this path; importing PyMJCF alone took 0.2 s of every arm run).

The text is what a run compiles and what its log embeds (model_source.xml), so it must compile to
the same model every time, bit for bit. MjSpec.to_xml() writes numbers with 6 significant digits,
so it cannot be that text. Instead the arm's XML is kept as written (attribute strings verbatim,
parsed with ElementTree) and MuJoCo attaches the payload itself: the payload's text becomes an
asset (``PAYLOAD_FILE``) that the arm loads with ``<asset><model/></asset>`` and places with
``<attach model=... prefix="payload/"/>`` inside a body at the site. MjSpec's attach prefixes the
payload's names and keeps its defaults apart, as PyMJCF's ``site.attach`` did.

What PyMJCF did that is kept, so that a model compiles exactly as it did when dm_control composed
it (same bodies in the same order, same names, masses, inertias and poses; checked in
tests/test_attach.py against logs written then):
- the attachment frame: a body named "payload/" inserted right after the site, with the site's
  pos, quat, axisangle, xyaxes, zaxis, euler and user; the payload's worldbody inside it;
- payload_mass: each payload geom's mass times payload_mass / (sum of the geom masses), written with
  repr (17 significant digits round-trip the double exactly);
- one <compiler> (angle, eulerseq, ...), <option> and <size> for arm and payload alike, merged from
  both as PyMJCF did (a setting only the payload makes applies to the arm too; a conflict is an
  error);
- an element that may be named and is not gets PyMJCF's name, "//unnamed_<kind>_<i>" (i counting
  that kind in document order; the payload's "payload//unnamed_<kind>_<i>");
- <include> files are merged into the including model's sections (after its own elements);
- files (meshes, textures, height fields, skins) are carried as assets named
  "<stem>-<sha1 of the contents><ext>", their directories (meshdir, texturedir, assetdir) resolved
  and dropped.
"""
from __future__ import annotations

import hashlib
import xml.etree.ElementTree as ET
from collections import OrderedDict
from pathlib import Path

from adaptive_mj.errors import ModelError

PREFIX = "payload/"
#: the payload's text in the composed model's assets; compile_spec hands *.xml assets to MuJoCo as
#: the files that <model file=...> and <include file=...> read
PAYLOAD_FILE = "payload.xml"
_PAYLOAD_MODEL = "adaptive_mj_payload"
_FRAME_ATTRIBUTES = ("pos", "quat", "axisangle", "xyaxes", "zaxis", "euler", "user")

# The kinds that PyMJCF names when the model does not: {tag: kind} by section.
_BODY_KINDS = {"body": "body", "joint": "joint", "freejoint": "joint", "geom": "geom", "site": "site",
               "camera": "camera", "light": "light"}
_SECTION_KINDS: dict[str, str | dict[str, str]] = {
    "asset": {t: t for t in ("material", "mesh", "texture", "hfield", "skin")},
    "actuator": "actuator", "sensor": "sensor", "tendon": "tendon", "equality": "equality",
    "contact": "contact", "keyframe": {"key": "key"},
    "custom": {t: t for t in ("numeric", "text", "tuple")},
}
# Files: (section, tag) -> (attributes naming files, the compiler's directory attribute for them).
_FILES = {"mesh": (("file",), "meshdir"), "hfield": (("file",), "meshdir"), "skin": (("file",), "meshdir"),
          "texture": (("file", "fileright", "fileleft", "fileup", "filedown", "filefront", "fileback"),
                      "texturedir")}
# Sections that a model has at most once (an included file's are merged into them).
_SINGLETONS = ("compiler", "option", "size", "visual", "statistic", "default", "custom", "asset", "worldbody",
               "contact", "equality", "tendon", "actuator", "sensor", "keyframe", "extension", "deformable")
_MAX_FILENAME = 998
# Settings PyMJCF merged from the payload into the one model (MuJoCo's attach would read the
# payload under its own compiler settings).
_MERGED = ("compiler", "option", "size")


def _parse(path: Path, what: str, read: list[tuple[Path, str]]) -> ET.Element:
    try:
        data = path.read_bytes()
    except OSError as exc:
        raise ModelError(f"{path}: cannot read the {what}: {exc.strerror or exc}") from None
    read.append((path, _sha1(data)))  # the bytes parsed: compose's cache checks them
    try:
        root = ET.fromstring(data)
    except ET.ParseError as exc:
        raise ModelError(f"{path}: could not parse the MJCF: {exc}") from None
    if root.tag != "mujoco":
        raise ModelError(f"{path}: could not parse the MJCF: the root element is <{root.tag}>, expected <mujoco>")
    return root


def _merge_includes(root: ET.Element, model_dir: Path, where: Path, read: list[tuple[Path, str]]) -> None:
    """Replace each <include file=.../> of `root` (any depth) by the file's elements, merged into
    root's sections as PyMJCF did; nested includes first. Paths are relative to the model's folder."""
    for parent in list(root.iter()):
        for inc in [c for c in parent if c.tag == "include"]:
            parent.remove(inc)
            name = inc.get("file")
            if not name:
                raise ModelError(f"{where}: could not parse the MJCF: an <include> without a file")
            path = model_dir / name
            if not path.is_file():
                raise ModelError(f"{where}: could not parse the MJCF: included file {str(path)!r} not found")
            sub = _parse(path, "included file", read)
            _merge_includes(sub, model_dir, path, read)
            if parent is not root:  # an include inside a section: its sections' contents go here
                for section in sub:
                    parent.extend(list(section) if section.tag in _SINGLETONS else [section])
                continue
            for section in sub:
                same = root.find(section.tag) if section.tag in _SINGLETONS else None
                if same is None:
                    root.append(section)
                else:
                    same.attrib.update({k: v for k, v in section.attrib.items() if k not in same.attrib})
                    same.extend(list(section))


def _carry_files(root: ET.Element, model_dir: Path, where: Path, assets: dict[str, bytes],
                 read: list[tuple[Path, str]]) -> None:
    """Each file an asset names, read into `assets` under PyMJCF's name for it; the XML names that."""
    dirs: dict[str, str] = {}
    for c in root.findall("compiler"):
        for attr in ("meshdir", "texturedir", "assetdir"):
            if attr in c.attrib:
                dirs[attr] = c.attrib.pop(attr)
    for section in root.findall("asset"):
        for el in section:
            attrs, dir_attr = _FILES.get(el.tag, ((), ""))
            base = dirs.get(dir_attr) or dirs.get("assetdir") or ""
            for attr in attrs:
                value = el.get(attr)
                if not value:
                    continue
                path = model_dir / base / value
                try:
                    data = path.read_bytes()
                except OSError as exc:
                    raise ModelError(f"{where}: <{el.tag}> {attr}={value!r}: cannot read {path}: "
                                     f"{exc.strerror or exc}") from None
                digest = _sha1(data)  # the asset's name, and what compose's cache checks
                read.append((path, digest))
                stem, ext = Path(value).stem, Path(value).suffix
                if attr == "file" and not el.get("name"):
                    el.set("name", stem)  # PyMJCF's name for an unnamed asset (MuJoCo's too)
                stem = stem[:max(0, _MAX_FILENAME - len(digest) - len(ext) - 1)]
                name = f"{stem}-{digest}{ext}"
                assets[name] = data
                el.set(attr, name)


def _load(path: Path, what: str, assets: dict[str, bytes], read: list[tuple[Path, str]]) -> ET.Element:
    root = _parse(path, what, read)
    _merge_includes(root, path.parent, path, read)
    _carry_files(root, path.parent, path, assets, read)
    return root


def _name_unnamed(root: ET.Element, lead: str) -> None:
    """PyMJCF's names for elements that may be named and are not: lead + "/unnamed_<kind>_<i>"
    (lead "/" in the arm; "" in the payload, whose names then get the prefix "payload/")."""
    count: dict[str, int] = {}

    def visit(el: ET.Element, kind: str | None) -> None:
        if kind is not None:
            i = count.get(kind, 0)
            count[kind] = i + 1
            if not el.get("name"):
                el.set("name", f"{lead}/unnamed_{kind}_{i}")

    def walk_body(parent: ET.Element) -> None:
        for el in parent:
            visit(el, _BODY_KINDS.get(el.tag))
            if el.tag in ("body", "frame"):
                walk_body(el)

    for section in root:
        if section.tag == "worldbody":
            walk_body(section)
            continue
        kinds = _SECTION_KINDS.get(section.tag)
        if kinds is None:
            continue
        for el in section:
            visit(el, kinds if isinstance(kinds, str) else kinds.get(el.tag))


def _merge_settings(root: ET.Element, load: ET.Element, tag: str, where: Path) -> None:
    """One <tag> (compiler, option, size) for arm and payload alike, as PyMJCF merged them: each
    attribute set by either, the same value if by both, else a one-line ModelError."""
    merged: dict[str, str] = {}
    for model in (root, load):
        for el in model.findall(tag):
            for k, v in el.attrib.items():
                if k in merged and merged[k] != v and not _same_numbers(merged[k], v):
                    raise ModelError(f"{where}: cannot attach the payload: its <{tag}> {k}={v!r} conflicts with "
                                     f"the arm's {k}={merged[k]!r}")
                merged.setdefault(k, v)
    if not merged:
        return
    for model in (root, load):
        els = model.findall(tag)
        if not els:
            els = [ET.Element(tag)]
            model.insert(0, els[0])
        for el in els:
            el.attrib.update(merged)


def _same_numbers(a: str, b: str) -> bool:
    try:
        return [float(x) for x in a.split()] == [float(x) for x in b.split()]
    except ValueError:
        return False


def _scale_masses(load: ET.Element, payload_mass: float, where: Path) -> None:
    """Each payload geom's mass times payload_mass / (their sum), as PyMJCF's attach path did."""
    world = load.find("worldbody")
    geoms = list(world.iter("geom")) if world is not None else []
    if not geoms or any(g.get("mass") is None for g in geoms):
        raise ModelError(f"{where}: every payload geom needs a mass attribute to scale it")
    try:
        masses = [float(g.get("mass", "")) for g in geoms]
    except ValueError:
        raise ModelError(f"{where}: a payload geom's mass is not a number") from None
    total = sum(masses)
    for g, m in zip(geoms, masses, strict=True):
        g.set("mass", repr(m * payload_mass / total))


def _text(root: ET.Element) -> str:
    return ET.tostring(root, encoding="unicode")


#: composed models kept (compose): a study's runs compose the same arm and payload thousands of times
COMPOSED_CACHE_SIZE = 32
_composed: OrderedDict[tuple, tuple[str, dict[str, bytes], tuple[tuple[Path, str], ...]]] = OrderedDict()


def _sha1(data: bytes) -> str:
    """SHA-1 of bytes, as hex: an asset's name (PyMJCF's) and compose's check of the files it read."""
    return hashlib.sha1(data).hexdigest()


def _digest(path: Path) -> str | None:
    """SHA-1 of a file's bytes, None if it cannot be read."""
    try:
        return _sha1(path.read_bytes())
    except OSError:
        return None


def compose(arm: Path, payload: Path | None, *, payload_mass: float | None = None,
            site: str = "tip") -> tuple[str, dict[str, bytes]]:
    """(MJCF text, assets): the arm with the payload attached at `site` (see the module docstring).
    payload None: the arm alone, through the same steps. Errors: one-line ModelErrors naming the file.

    The result is kept per (arm, payload, payload_mass, site) and given again while every file it read
    (the arm, the payload, their includes and asset files) has the same bytes (SHA-1, read again at each
    call: a few µs a small file, where composing cost a 6-joint run 1 ms of ElementTree work)."""
    key = (str(Path(arm).resolve()), None if payload is None else str(Path(payload).resolve()),
           payload_mass, site)
    hit = _composed.get(key)
    if hit is not None and all(_digest(p) == digest for p, digest in hit[2]):
        _composed.move_to_end(key)
        return hit[0], dict(hit[1])
    read: list[tuple[Path, str]] = []
    text, assets = _compose(Path(arm), None if payload is None else Path(payload), payload_mass, site, read)
    _composed[key] = (text, dict(assets), tuple(read))
    while len(_composed) > COMPOSED_CACHE_SIZE:
        _composed.popitem(last=False)
    return text, assets


def _compose(arm: Path, payload: Path | None, payload_mass: float | None, site: str,
             read: list[tuple[Path, str]]) -> tuple[str, dict[str, bytes]]:
    """compose, every time (`read` gets each file read, with the SHA-1 of its bytes)."""
    assets: dict[str, bytes] = {}
    root = _load(arm, "model file", assets, read)
    root.set("model", root.get("model") or "unnamed_model")
    if payload is None:
        _name_unnamed(root, "/")
        return _text(root), assets
    load = _load(payload, "payload file", assets, read)
    _name_unnamed(load, "")
    if payload_mass is not None:
        _scale_masses(load, payload_mass, payload)
    for tag in _MERGED:
        _merge_settings(root, load, tag, payload)

    world = root.find("worldbody")
    parents = {child: el for el in (world.iter() if world is not None else ()) for child in el}
    tip = next((s for s in parents if s.tag == "site" and s.get("name") == site), None)
    if tip is None:
        sites = [s.get("name") for s in (world.iter("site") if world is not None else ()) if s.get("name")]
        raise ModelError(f"{arm}: no site named {site!r} to attach the payload to (the model has sites "
                         f"{sites}; set plant.site, or plant.payload = \"none\")")
    parent = parents[tip]
    frame = ET.Element("body", {a: v for a in _FRAME_ATTRIBUTES if (v := tip.get(a)) is not None})
    frame.set("name", PREFIX)
    ET.SubElement(frame, "attach", {"model": _PAYLOAD_MODEL, "prefix": PREFIX})
    parent.insert(list(parent).index(tip) + 1, frame)
    _name_unnamed(root, "/")  # the frame counts among the bodies, as in PyMJCF
    section = root.find("asset")
    if section is None:
        section = ET.Element("asset")
        root.insert(0, section)
    ET.SubElement(section, "model", {"name": _PAYLOAD_MODEL, "file": PAYLOAD_FILE})
    assets[PAYLOAD_FILE] = _text(load).encode("utf-8")
    return _text(root), assets
