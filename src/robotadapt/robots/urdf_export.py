"""A copy of a URDF holding identified inertial parameters: read back with the same locked joints, it gives them exactly.

The parameters are those of :meth:`.kinematic_tree.KinematicTree.from_urdf`'s model, one row of 10 per moving joint
(`link_params`, Pinocchio's order: m, m c, the inertia about the joint frame's origin). That model has one body per
moving joint: the joint's child link (its frame is the joint frame) with every link hanging from it through fixed
joints (merged by Pinocchio's URDF parser) and locked joints (merged by `buildReducedModel`), e.g. the Panda's hand and
fingers in link 7. The copy gives the child link the body's whole inertia, `<origin xyz="c" rpy="0 0 0">` and the
inertia about c, and removes the `<inertial>` of every link merged into it: a link without one is massless (Pinocchio
reads a zero inertia, silently, as for the Panda's own massless `panda_link8`), so nothing counts twice. Links merged
into the fixed base keep theirs; everything else (kinematics, limits, visuals, collisions, mesh paths, comments) is kept
as it was. Mesh paths stay as written: a relative or `package://` one may not resolve next to the copy, which Pinocchio's
dynamics never needs (it reads no mesh).
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from xml.etree import ElementTree

import numpy as np

from ..files import atomic_write, writable_dir
from ..validation import ConfigError, as_array
from .base import Array
from .kinematic_tree import KinematicTree

_PAIRS = {"ixx": (0, 0), "ixy": (0, 1), "iyy": (1, 1), "ixz": (0, 2), "iyz": (1, 2), "izz": (2, 2)}  # φ's order


def write_identified_urdf(source: str | Path, locked: Sequence[str], link_params: Array, out: Path) -> None:
    """Write to `out` a copy of the URDF `source` whose model with the joints `locked` has the standard parameters
    `link_params` (n, 10), one row per moving joint in the model's order; a row that is no rigid body (mass ≤ 0, or an
    inertia about the centre of mass that is not positive semidefinite) is refused."""
    tree = KinematicTree.from_urdf(source, locked)
    params = as_array(link_params, "link_params")
    if params.shape != (tree.n, 10):
        raise ConfigError("link_params", f"expected one row of 10 parameters per moving joint of {Path(source).name}, "
                          f"shape {(tree.n, 10)}, got {params.shape}")
    inertials = [_inertial(row, f"row {i} ({name})")
                 for i, (row, name) in enumerate(zip(params, tree.joint_names, strict=True))]
    data = Path(source).read_bytes()
    root = ElementTree.fromstring(data, ElementTree.XMLParser(target=ElementTree.TreeBuilder(insert_comments=True)))
    links = {str(link.get("name")): link for link in root.findall("link")}
    joints = {joint.get("name"): joint for joint in root.findall("joint")}
    owners = _owners(root, set(tree.joint_names))
    bodies = {_end(joints[name], "child"): inertial for name, inertial in zip(tree.joint_names, inertials, strict=True)}
    for name, link in links.items():
        if name in bodies:
            _set_inertial(link, *bodies[name])
        elif owners[name] is not None:
            for element in link.findall("inertial"):
                link.remove(element)
    origin = str(Path(source).resolve()).replace("--", "- -")  # "--" may not appear in an XML comment
    head = [f" inertial parameters identified by robotadapt identify; the rest as in {origin} ", *_prolog(data)]
    text = "".join(['<?xml version="1.0" encoding="utf-8"?>\n',
                    *(ElementTree.tostring(ElementTree.Comment(c), encoding="unicode") + "\n" for c in head),
                    ElementTree.tostring(root, encoding="unicode"), "\n"])
    writable_dir(out.parent)
    atomic_write(out, lambda f: f.write(text.encode("utf-8")), binary=True)


def _inertial(row: Array, where: str) -> tuple[float, Array, Array]:
    """(m, c, I_c) of one row [m, m c, I about the frame origin], I_c = I − m(‖c‖² 𝟙 − c cᵀ) about the centre of mass."""
    m = float(row[0])
    if not m > 0:
        raise ConfigError("link_params", f"{where}: the mass must be positive, got {m:g}")
    c = row[1:4] / m
    inertia = np.array([[row[4], row[5], row[7]], [row[5], row[6], row[8]], [row[7], row[8], row[9]]])
    about_c = inertia - m * (c @ c * np.eye(3) - np.outer(c, c))
    eig = np.linalg.eigvalsh(about_c)
    if eig.min() < -1e-12 * max(1.0, float(np.abs(eig).max())):
        raise ConfigError("link_params", f"{where}: the inertia about the centre of mass is not positive semidefinite "
                          f"(smallest eigenvalue {eig.min():.3g}): no rigid body has it; give a physically consistent "
                          "estimate")
    return m, c, about_c


def _end(joint: ElementTree.Element, tag: str) -> str:
    """The link a joint's `<parent>` or `<child>` names."""
    element = joint.find(tag)
    return "" if element is None else str(element.get("link"))


def _owners(root: ElementTree.Element, moving: set[str]) -> dict[str, str | None]:
    """Each link's body: the moving joint whose child it is or hangs from through fixed and locked joints (None: the
    fixed base)."""
    parents = {_end(joint, "child"): joint for joint in root.findall("joint")}
    owners: dict[str, str | None] = {}

    def owner(link: str) -> str | None:
        if link not in owners:
            joint = parents.get(link)
            if joint is None:
                owners[link] = None
            else:
                name = str(joint.get("name"))
                owners[link] = name if name in moving else owner(_end(joint, "parent"))
        return owners[link]

    for link in root.findall("link"):
        owner(str(link.get("name")))
    return owners


def _set_inertial(link: ElementTree.Element, m: float, c: Array, about_c: Array) -> None:
    """Give `link` the inertial (m, c, I_c), in place of its own (its elements kept where they were)."""
    inertial = link.find("inertial")
    if inertial is None:
        inertial = ElementTree.SubElement(link, "inertial")
    values = {"origin": {"xyz": " ".join(repr(float(x)) for x in c), "rpy": "0 0 0"}, "mass": {"value": repr(m)},
              "inertia": {key: repr(float(about_c[i, j])) for key, (i, j) in _PAIRS.items()}}
    for tag, attributes in values.items():
        element = inertial.find(tag)
        if element is None:
            element = ElementTree.SubElement(inertial, tag)
        element.attrib.clear()
        element.attrib.update(attributes)


def _prolog(data: bytes) -> list[str]:
    """The comments before the root element (the tree keeps only those inside it)."""
    parser: ElementTree.XMLPullParser = ElementTree.XMLPullParser(events=("start", "comment"))
    parser.feed(data)
    out = []
    for event, element in parser.read_events():  # type: ignore[misc]  # typeshed: (event, element) pairs
        if event == "start":
            break
        out.append(str(getattr(element, "text", "")))
    return out
