"""An effect of diagnosis.json's `effects` in words: its plain name and its size."""

from __future__ import annotations

_KIND_WORDS = {
    "offset": "a constant effort offset on {joints}",
    "armature": "extra reflected motor inertia on {joints}",
    "gravity_tilt": "gravity tilted against the model (base not level)",
    "time_shift": "efforts recorded late against the positions",
    "effort_scale": "the efforts measured to a wrong scale (the controller's effort scale off)",
    "counterweight_transmission": "an error in the counterweight cable's transmission to {joints}",
}


def plain_name(entry: dict) -> str:
    """An effect of diagnosis.json's `effects` in words (its `name` is the
    library's identifier, e.g. friction_q3_presliding0.0001)."""
    name, kind, joints = entry["name"], entry.get("kind", ""), ", ".join(entry.get("joints", ()))
    reversal = (entry.get("parameters") or {}).get("reversal")
    how = "" if reversal in (None, "sign") else f", reversing over {reversal.removeprefix('Dahl over ').split(',')[0]}" + (
        " (pre-sliding)" if reversal.startswith("Dahl") else "")
    if kind == "friction":
        if name.startswith("position_friction"):
            return f"friction of {joints} that changes along its range{how}"
        if name.startswith("presliding_of_"):  # presliding_of_<link>_<distance>: the identified Coulomb level, its reversal spread
            link, distance = name.removeprefix("presliding_of_").rsplit("_", 1)
            return f"the identified friction of {link} ({joints}) reversing gradually over {distance} (pre-sliding)"
        if len(entry.get("joints", ())) > 1:
            return f"friction of the coupled joints {joints}{how}"
        return f"{'Stribeck ' if name.startswith('stribeck') else ''}friction of {joints}{how}"
    if kind == "elastic":
        return f"{'a torsion spring' if name.startswith('torsion') else 'cable elasticity'} on {joints}"
    if kind == "load":  # AngleLoad: angle_load_<joint>_by_<source>
        return f"a load on {joints} set by {name.split('_by_')[-1]}'s angle, whatever the motion's direction (a cable, a harness)"
    if kind in ("payload", "payload_at_position", "gravity_mismatch"):
        link = name.split("_on_")[-1].split("_at_")[-1]
        return f"a payload on the {link} link" if kind != "gravity_mismatch" else f"a gravity mismatch on the {link} link (mass distribution)"
    if kind == "mass_scale":
        return f"the {name.removeprefix('mass_scale_')} link's own mass and inertia off the identified ones"
    return _KIND_WORDS.get(kind, name).format(joints=joints)


#: a fitted size below this (in its unit) is the bounded fit's round-off around zero
ROUND_OFF = 1e-12


def size_words(entry: dict) -> str:
    size, units = entry.get("size"), entry.get("units") or {}
    unit = next(iter(units.values()), "")
    if not isinstance(size, (int, float)):
        return ""
    if entry.get("kind") == "effort_scale":
        return f", {abs(size):.1%} {'low' if size < 0 else 'high'}"
    if entry.get("kind") == "mass_scale":
        return f", {abs(size):.0%} {'lighter' if size < 0 else 'heavier'}"
    viscous = (entry.get("parameters") or {}).get("viscous")
    if entry.get("kind") == "friction" and isinstance(viscous, (int, float)):  # a viscous change read "size 0 N" (its Coulomb)
        # a part the bounded fit holds at zero comes back as round-off (4.83e-40): zero
        size, viscous = (0.0 if abs(x) < ROUND_OFF else x for x in (size, viscous))
        along = (entry.get("parameters") or {}).get("coulomb_within_runs")  # a table along the range: its span, not its largest knot
        low, high = (0.0 if abs(x) < ROUND_OFF else x for x in along) if along else (None, None)  # 7.92e-30 read as a level
        coulomb = f"{low:.3g} to {high:.3g} {unit} along the runs' range" if along else f"{size:.3g} {unit}"
        return f", Coulomb {coulomb}, viscous {viscous:.3g} {units.get('viscous', '')}".rstrip()
    return f", {size:.0%} of the identified term" if unit == "1" else f", size {size:.3g} {unit}".rstrip()
