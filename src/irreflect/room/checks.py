"""What a scene's materials say of themselves, before a simulation uses them.

A material file written by ``irreflect fit --save`` carries its fit's verdict and warnings
(:mod:`irreflect.verdict`): ``irreflect room`` and ``irreflect reproduce --scene`` print
them for every material they use, so a floor fitted from a lobe seen by one receiver does
not enter a room without a word. A material whose model predicts negative power anywhere
in the room's range (:func:`irreflect.room.materials.negative_power`) is refused unless
the caller allows it: the room would clip the negative part and simulate another curve
than the one fitted.
"""

from __future__ import annotations

from ..errors import SceneError
from .materials import fit_notes


def used_materials(scene) -> list[str]:
    """The names of the materials a scene's room faces and boxes use, in first-use order."""
    names = list(scene.room_materials)
    for box in scene.boxes:
        names += list(box.materials)
    return list(dict.fromkeys(names))


def material_notes(scene, allow_unphysical: bool = False) -> list[str]:
    """One block of lines per used material that has anything to say (its fit's verdict
    and warnings, an unphysical model). Raises SceneError for an unphysical material
    unless ``allow_unphysical`` (then it is a warning line)."""
    lines, refused = [], []
    for name in used_materials(scene):
        mat = scene.materials[name]
        notes = fit_notes(mat)
        if not notes:
            continue
        lines.append(f"material '{name}' ({mat.source}):")
        lines += [f"  {n}" for n in notes]
        if (mat.metadata or {}).get("unphysical"):
            refused.append(f"'{name}': {mat.metadata['unphysical']}")
    if refused and not allow_unphysical:
        raise SceneError(
            f"{scene.path or scene.name}: material {refused[0]}: fit another model (the "
            "two-lobe model's share saturates and never goes negative) or pass "
            "--allow-unphysical to simulate it with the negative part clipped to 0")
    return lines
