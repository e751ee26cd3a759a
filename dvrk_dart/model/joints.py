"""The one place that knows the joint order and units of the PSM coordinates.

Coordinates are those of the identification model (Wang et al. 2019): q1 yaw,
q2 pitch, q3 insertion, q4 tool roll, and q5..q7 the three wrist/jaw *motor*
coordinates (see models/psm/README.md).
"""

JOINT_NAMES = ("q1", "q2", "q3", "q4", "q5", "q6", "q7")
N_JOINTS = len(JOINT_NAMES)
PRISMATIC_JOINTS = ("q3",)
#: index of the insertion joint (the only prismatic one)
INSERTION = JOINT_NAMES.index("q3")


def position_unit(name: str) -> str:
    return "m" if name in PRISMATIC_JOINTS else "rad"


def effort_unit(name: str) -> str:
    return "N" if name in PRISMATIC_JOINTS else "N·m"


def column_names(prefix: str) -> list[str]:
    """['tau1', ..., 'tau7'] for prefix 'tau'."""
    return [f"{prefix}{i + 1}" for i in range(N_JOINTS)]
