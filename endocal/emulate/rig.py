"""An emulated thesis rig: Dynamixel knob servos and an NDI Aurora whose sensors follow the knobs.

:class:`EmulatedRig` starts an emulated servo bus (:mod:`endocal.emulate.servos`) and an
emulated Aurora (:mod:`endocal.emulate.aurora`), and a physics thread that, every
``physics_period_s``, reads the servos' present positions and steps the simulator
(:mod:`endocal.sim`) with them as knob positions, serving the tip and base sensor poses it
computes through the Aurora. The simulator's own knob servo is switched off (the emulated
servo is the lag now); everything else (tendon-sheath friction, slack, the bending section,
the tracker's noise and latency) is the simulator's, as in a ``--backend sim`` run.

:meth:`EmulatedRig.write_config` writes a rig TOML pointing at the emulators, so that
``endocal excite PROTOCOL --backend hardware --hardware-config rig.toml`` runs unchanged
through the real ``dynamixel-sdk``, ``scikit-surgerynditracker`` and ``ndicapi``.
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from endocal.emulate._serving import Served
from endocal.emulate.aurora import AuroraEmulator, AuroraFaults
from endocal.emulate.servos import BusFaults, ServoBus
from endocal.emulate.stage import StageEmulator, StageFaults
from endocal.probe import ProbeConfig
from endocal.sim import SimConfig, Simulator

ZERO_TICKS = 2048
TICKS_PER_DEG = 4096 / 360.0
#: What the rig TOML allows each status packet (2 x this + 2 ms) and each stage reply: the emulators
#: answer from threads of a process that shares the CPU with the host, and a loaded machine does not
#: always schedule them within the 34 ms dynamixel-sdk waits for a U2D2 (round trips of 0.3 s were
#: measured on 2 cores under a load of 12), which on a real rig would be a dead bus
LATENCY_TIMER_MS = 500.0
STAGE_TIMEOUT_S, STAGE_MAX_MISSED = 0.1, 10  # a stage silent for 1.1 s stops the run


class EmulatedRig(Served):
    """Servo bus + Aurora + the simulator's probe between them.

    Parameters
    ----------
    probe : ProbeConfig
    sim_config : SimConfig, optional
        The probe's physics (default: the simulator's defaults); its knob servo is replaced.
    seed : int
        Seed of the simulator's noise.
    ids : dict, optional
        Bending axis -> servo ID (default 1 and 2).
    bus_faults, aurora_faults : optional
        Faults of the two devices.
    present_ticks : int or dict
        Where the knob servos start (ticks, for all or per servo ID; 2048 is 0 deg).
    torque_on : bool
        The servos start with torque on (as a crashed program leaves them).
    physics_period_s : float
        How often the probe is stepped (default 5 ms).
    stage : bool
        Also emulate the UDP translation/rotation stage (the probe follows its drives).
    stage_faults : StageFaults, optional
    on_event : callable, optional
        One line per device event (torque switching, faults).
    """

    def __init__(self, probe: ProbeConfig, sim_config: SimConfig | None = None, *, seed: int = 0, ids: dict | None = None,
                 bus_faults: BusFaults | None = None, aurora_faults: AuroraFaults | None = None,
                 physics_period_s: float = 0.005, baudrate: int = 57600, present_ticks=ZERO_TICKS,
                 torque_on: bool = False, stage: bool = False, stage_faults: StageFaults | None = None,
                 on_event=None) -> None:
        super().__init__()
        self.probe = probe
        self.ids = ids or {a: k + 1 for k, a in enumerate(probe.bending_axes)}
        cfg = (sim_config or SimConfig.default()).replace(motor={"knob_time_constant_s": 0.0})
        self.sim = Simulator(cfg, probe, seed)
        self.bus = ServoBus(list(self.ids.values()), baudrate=baudrate, present_ticks=present_ticks,
                            torque_on=torque_on, faults=bus_faults, seed=seed, on_event=on_event)
        self.aurora = AuroraEmulator(faults=aurora_faults)
        self.stage = StageEmulator(0, faults=stage_faults, on_event=on_event) if stage else None
        self.period_s = physics_period_s
        self._t0 = 0.0
        self.steps = 0
        self.error: BaseException | None = None

    thread_name = "rig-physics"

    def _open(self) -> None:
        self.bus.start()
        self.aurora.start()
        if self.stage is not None:
            self.stage.start()
        self._t0 = time.monotonic()
        self._step(1e-6)  # poses at rest before anyone asks

    def _release(self) -> None:
        if self.stage is not None:
            self.stage.close()
        self.aurora.close()
        self.bus.close()

    def _step(self, t: float) -> None:
        ticks = self.bus.positions_ticks()
        goal = {d: np.array([0.0]) for d in self.probe.dofs}
        for axis, i in self.ids.items():
            goal[axis] = np.array([(ticks[i] - ZERO_TICKS) / TICKS_PER_DEG])
        if self.stage is not None:  # the probe translates and rotates where the stage's drives are
            goal["translation"], goal["rotation"] = (np.array([v]) for v in self.stage.position)
        chunk = self.sim.execute(np.array([t]), goal)
        tr = chunk.tracker
        if len(tr["t_s"]):
            poses = {}
            for sensor in ("tip", "base"):
                k = np.flatnonzero(tr["sensor"] == sensor)
                if k.size:
                    j = k[-1]
                    ok = bool(tr["valid"][j])
                    poses[sensor] = ((tr["x_mm"][j], tr["y_mm"][j], tr["z_mm"][j]),
                                     (tr["qw"][j], tr["qx"][j], tr["qy"][j], tr["qz"][j])) if ok else None
            self.aurora.set_poses(poses)
        self.steps += 1

    def _serve(self) -> None:
        next_t = time.monotonic()
        try:
            while not self._stop.is_set():
                now = time.monotonic()
                self._step(max(now - self._t0, self.sim_time() + 1e-6))
                next_t += self.period_s
                self._stop.wait(max(0.0, next_t - time.monotonic()))
        except BaseException as exc:  # noqa: BLE001 - reported by the command that runs the rig
            self.error = exc

    def sim_time(self) -> float:
        return float(self.sim._t_last or 0.0)

    def write_config(self, path: str | Path) -> Path:
        """A rig TOML pointing at the emulated devices, for ``--hardware-config``."""
        path = Path(path)
        motors = "".join(
            f"\n[dynamixel.motors.{axis}]\nid = {i}\nzero_ticks = {ZERO_TICKS}\ndirection = 1\n"
            f"limits_deg = [{self.probe.knob_limits_deg[axis][0]:g}, {self.probe.knob_limits_deg[axis][1]:g}]\n"
            for axis, i in self.ids.items())
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(
            "# Written by `endocal emulate rig`: the emulated devices of this session.\n"
            'name = "emulated rig"\n\n'
            f'[dynamixel]\nport = "{self.bus.port}"\nbaudrate = {self.bus.baudrate}\nmodel_number = 1020\n'
            f"latency_timer_ms = {LATENCY_TIMER_MS:g}  # served by a process that shares the CPU\n"
            f"{motors}\n"
            f'[tracker]\nserial_port = "{self.aurora.port}"\ntip_port_handle = {self.aurora.handles["tip"]}\n'
            f'base_port_handle = {self.aurora.handles["base"]}\ndetect_timeout_s = 3.0\n\n'
            + ('[stage]\nmode = "absent"\n' if self.stage is None else
               f'[stage]\nmode = "udp"\nhost = "127.0.0.1"\nport = {self.stage.port}\ntimeout_s = {STAGE_TIMEOUT_S:g}\n'
               f'max_missed_replies = {STAGE_MAX_MISSED}\ntranslation_limits_mm = [-50.0, 50.0]\nrotation_limits_deg = [-90.0, 90.0]\n'))
        return path
