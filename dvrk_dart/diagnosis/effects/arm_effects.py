"""Effects of the whole arm or of the measurement: base tilt, time shift, effort scale, counterweight transmission,
a link's own mass."""

from __future__ import annotations

import numpy as np

from dvrk_dart.diagnosis.effects.effect import Effect, Parameter, SimContribution
from dvrk_dart.diagnosis.effects.geometry import joints_moving_link
from dvrk_dart.io.arm import Arm
from dvrk_dart.model.joints import JOINT_NAMES, N_JOINTS

#: the largest base mounting tilt considered (rad, about 2.9 degrees): a
#: larger one would be visible by eye and is not a plausible unknown
TILT_LIMIT_RAD = 0.05
#: the largest time shift between positions and efforts considered (s):
#: 10 samples at 200 Hz, far beyond any controller latency of the dVRK
TIME_SHIFT_LIMIT_S = 0.05
#: efforts measured off by more than 30 % are another arm's configuration, not a scale to look for in a gap
EFFORT_SCALE_LIMIT = 0.3
#: the counterweight tendon cannot transmit more than +-50 % of its force wrongly
COUNTERWEIGHT_SCALE_LIMIT = 0.5
#: a tension-proportional tendon loss beyond 50 % is not a transmission
COUNTERWEIGHT_LOSS_LIMIT = 0.5
#: a link's own mass off the identified one by more than 50 % is another arm, not an error of its model
MASS_SCALE_LIMIT = 0.5


def gravity_tilt_directions(gravity: np.ndarray) -> np.ndarray:
    """d(gravity in base)/d(tilt_x, tilt_y) at zero tilt, (3, 2).

    Convention of `dart_builder.gravity_in_base`: the base frame is
    R = Rx(tilt_x) Ry(tilt_y) in the world and gravity in base coordinates is
    R^T g, so to first order g_base = g - (tilt_x e_x + tilt_y e_y) x g."""
    g = np.asarray(gravity, dtype=float)
    return np.column_stack([-np.cross([1.0, 0.0, 0.0], g), -np.cross([0.0, 1.0, 0.0], g)])



class TimeShift(Effect):
    """Efforts recorded late (delta > 0) relative to the positions:
    tau_meas(t) = tau(t - delta) ~ tau(t) - delta dtau/dt, tau what the arm exerts
    (`TrajectoryFeatures.exerted_effort`: against a baseline of the same motion its measured effort, whose friction
    reversals the simulation lacks)."""

    kind = "time_shift"
    name = "time_shift"
    joints = JOINT_NAMES
    parameters = (Parameter("delay_s", "s", -TIME_SHIFT_LIMIT_S, TIME_SHIFT_LIMIT_S),)

    def columns(self, features):
        return -features.exerted_rate[:, :, None]

    def sim_contribution(self, p):
        return None  # a property of the measurement, not of the physics


class EffortScale(Effect):
    """Every joint's efforts measured times (1 + s): tau_meas = (1 + s) tau, a gap of s tau, tau what the arm exerts
    (`TrajectoryFeatures.exerted_effort`). candidate=False: never selected, only weighed against what the selected
    effects explain (`scale_rival`)."""

    kind = "effort_scale"
    name = "effort_scale"
    joints = JOINT_NAMES
    parameters = (Parameter("scale_error", "1", -EFFORT_SCALE_LIMIT, EFFORT_SCALE_LIMIT),)

    def __init__(self, candidate: bool = True):
        self.candidate = candidate

    def columns(self, features):
        return features.exerted_effort[:, :, None]

    def sim_contribution(self, p):
        return None  # a property of the measurement, not of the physics


class GravityTilt(Effect):
    """Base mounted with a small tilt about base x, then y (dart_builder's
    convention): the gravity efforts of the identified bodies for the gravity
    direction change, linearised in the two angles."""

    kind = "gravity_tilt"
    name = "gravity_tilt"
    parameters = (
        Parameter("tilt_x_rad", "rad", -TILT_LIMIT_RAD, TILT_LIMIT_RAD),
        Parameter("tilt_y_rad", "rad", -TILT_LIMIT_RAD, TILT_LIMIT_RAD),
    )

    def __init__(self, arm: Arm):
        self.directions = gravity_tilt_directions(arm.model.gravity)
        massive = [k for k, l in arm.model.links.items() if l.body and arm.params[k].mass > 0.0]
        moved = set().union(*(joints_moving_link(arm.model, k) for k in massive))
        self.joints = tuple(j for j in JOINT_NAMES if j in moved)

    def columns(self, features):
        return features.unit_gravity_efforts @ self.directions

    def sim_contribution(self, p):
        return SimContribution(gravity_tilt_rad=np.array([p[0], p[1]], dtype=float))

    def size(self, p):
        return float(np.hypot(p[0], p[1]))


class CounterweightTransmission(Effect):
    """The counterweight tendon transmits its force F to J3 with a scale error
    (1 + kappa) and a tension-proportional loss mu |F| sign(dq3)."""

    kind = "counterweight_transmission"
    name = "counterweight_transmission"
    joints = ("q3",)
    parameters = (
        Parameter("force_scale_error", "1", -COUNTERWEIGHT_SCALE_LIMIT, COUNTERWEIGHT_SCALE_LIMIT),
        Parameter("loss_coefficient", "1", 0.0, COUNTERWEIGHT_LOSS_LIMIT),
    )

    def __init__(self, arm: Arm):
        self.leader = JOINT_NAMES.index("q3")

    def columns(self, features):
        force = features.counterweight_effort[:, self.leader]
        out = np.zeros((len(features), N_JOINTS, 2))
        out[:, self.leader, 0] = force
        out[:, self.leader, 1] = np.abs(force) * np.sign(features.dq[:, self.leader])
        return out

    def sim_contribution(self, p):
        return None  # SimConfig's tendon is ideal (or the paper's PID)


def prismatic_bodies(arm: Arm) -> list[int]:
    """The links with mass that only prismatic coordinates move (the PSM's insertion carriage and counterweight):
    along a prismatic joint gravity and inertia see the mass alone, which a payload can only raise, so an arm
    lighter there than identified has no other candidate (on a revolute joint a payload beyond the axis lowers
    a link's gravity)."""
    prismatic = {JOINT_NAMES.index(j) for j in arm.model.prismatic_coordinates}
    return [key for key, link in arm.model.links.items()
            if link.body and arm.params[key].mass > 0.0 and link.variable is not None
            and set(np.flatnonzero(link.variable.coeffs)) <= prismatic]


class LinkMassScale(Effect):
    """A link lighter or heavier than identified: its mass and inertia times
    (1 + error), its centre of mass where it is, so every effort of the body
    scales (simulated: the DART body's inertia, `JointEffects.link_mass_scale`).
    The arm's own: with a baseline of the same motion it is no candidate (a
    session does not change a link's mass; a payload does)."""

    kind = "mass_scale"
    parameters = (Parameter("mass_error", "1", -MASS_SCALE_LIMIT, MASS_SCALE_LIMIT),)

    def __init__(self, arm: Arm, key: int):
        self.link_key = key
        self.is_counterweight = key == arm.model.counterweight_link
        self.name = f"mass_scale_{arm.model.links[key].name}"
        self.joints = tuple(j for j in JOINT_NAMES if j in joints_moving_link(arm.model, key))

    def columns(self, features):
        return features.body_effort(self.link_key)[:, :, None]

    @property
    def family(self) -> str:
        """The counterweight's: one with the tendon's transmission error, whose force scale has the same J3
        column (the counterweight's own efforts); they differ only by its small J1 and J2 efforts."""
        return CounterweightTransmission.name if self.is_counterweight else self.name

    def sim_contribution(self, p):
        return SimContribution(link_mass_scale=((float(self.link_key), float(p[0])),))
