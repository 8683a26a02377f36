"""`endocal emulate rig|dynamixel|aurora|stage`: emulated rig devices that speak the real wire protocols.

Each command starts its emulator, prints where to reach it on one line, then one line per
event (a servo's torque switching, an injected fault), and runs until Ctrl-C or SIGTERM.
"""

from __future__ import annotations

import signal
import threading
from pathlib import Path
from typing import Optional

import typer

from endocal.cli._common import cli_errors, out

app = typer.Typer(help="Emulated rig devices speaking the real wire protocols, for rehearsals and tests.",
                  no_args_is_help=True)


def _run_until_stopped(emulator, ready: str, final=None) -> None:
    """Print the ``ready`` line, serve until Ctrl-C or SIGTERM, then close the emulator and print
    ``stopped`` (with ``final()``, e.g. every servo's torque state, when given).

    SIGTERM is caught before ``ready`` is printed: whoever waits for that line may stop us at once.
    """
    stop = threading.Event()
    previous = signal.signal(signal.SIGTERM, lambda *_: stop.set())
    try:
        out.print(ready, markup=False)
        while not stop.wait(0.2):
            pass
    except KeyboardInterrupt:
        pass
    finally:
        signal.signal(signal.SIGTERM, previous)
        emulator.close()
        out.print("stopped" if final is None else f"stopped: {final()}", markup=False)


def _hardware_errors(items: list[str]) -> dict[int, str]:
    """``--hardware-error ID=overload`` options as servo ID -> kind."""
    from endocal.emulate.servos import HW_ERRORS
    from endocal.errors import ConfigError

    errors = {}
    for item in items:
        k, sep, kind = item.partition("=")
        if not sep or not k.strip().isdigit() or kind not in HW_ERRORS:
            raise ConfigError(f"--hardware-error {item!r}: write ID=overload or ID=overheating")
        errors[int(k)] = kind
    return errors


def _aurora_faults(missing, missing_after, silent_after, out_of_volume, partly_out_of_volume, out_of_volume_after,
                   out_of_volume_for, silent_flag="--silent-after"):
    """The Aurora's fault options as :class:`~endocal.emulate.aurora.AuroraFaults`; sensors named tip or base."""
    from endocal.emulate.aurora import AuroraFaults
    from endocal.errors import ConfigError

    for flag, sensors in (("--missing", missing), ("--out-of-volume", out_of_volume),
                          ("--partly-out-of-volume", partly_out_of_volume)):
        bad = [m for m in sensors if m not in ("tip", "base")]
        if bad:
            raise ConfigError(f"{flag} {bad[0]!r}: name a sensor, tip or base")
    if silent_after is not None and silent_after < 0:
        raise ConfigError(f"{silent_flag} {silent_after:g}: give 0 s (never answers) or more")
    if out_of_volume_after < 0 or (out_of_volume_for is not None and not out_of_volume_for > 0):
        raise ConfigError("--out-of-volume-after must be 0 s or more and --out-of-volume-for more than 0 s")
    return AuroraFaults(missing=tuple(missing), missing_after_s=missing_after, silent_after_s=silent_after,
                        out_of_volume=tuple(out_of_volume), partly_out_of_volume=tuple(partly_out_of_volume),
                        out_of_volume_after_s=out_of_volume_after, out_of_volume_for_s=out_of_volume_for)


def _event(line: str) -> None:
    out.print(line, markup=False)


@app.command("dynamixel")
@cli_errors
def dynamixel(
    ids: str = typer.Option("1,2", "--ids", help="Servo IDs on the bus, comma-separated."),
    baudrate: int = typer.Option(57600, "--baud", help="Baud rate the servos answer at."),
    model_number: int = typer.Option(1020, "--model-number", help="What the servos answer a ping with (1020: XM430-W350)."),
    drop: float = typer.Option(0.0, "--drop", help="Fault: probability of losing each reply."),
    corrupt: float = typer.Option(0.0, "--corrupt", help="Fault: probability of a wrong CRC on each reply."),
    delay_ms: float = typer.Option(0.0, "--delay-ms", help="Fault: hold every reply back this long."),
    unplug_after: Optional[float] = typer.Option(None, "--unplug-after", help="Fault: the bus goes silent this many seconds after the first packet."),
    hardware_error: list[str] = typer.Option([], "--hardware-error", help="Fault: ID=overload or ID=overheating (repeatable), raised --hardware-error-after seconds in."),
    hardware_error_after: float = typer.Option(5.0, "--hardware-error-after", help="Seconds after the first packet."),
    seed: int = typer.Option(0, "--seed", help="Seed of the lost and corrupted replies."),
) -> None:
    """An emulated bus of Dynamixel XM430-W350 servos on a pseudo-terminal (Protocol 2.0).

    Point `[dynamixel] port` of a rig TOML at the printed path.
    """
    from endocal.emulate.servos import BusFaults, ServoBus
    from endocal.errors import ConfigError

    try:
        id_list = [int(x) for x in ids.split(",") if x.strip()]
    except ValueError:
        raise ConfigError(f"--ids {ids!r}: give servo IDs as integers, e.g. --ids 1,2") from None
    errors = _hardware_errors(hardware_error)
    faults = BusFaults(drop_probability=drop, corrupt_probability=corrupt, delay_s=delay_ms / 1000.0,
                       unplug_after_s=unplug_after, hardware_error=errors, hardware_error_after_s=hardware_error_after)
    bus = ServoBus(id_list, model_number=model_number, baudrate=baudrate, faults=faults, seed=seed, on_event=_event)
    bus.start()
    _run_until_stopped(bus, f"dynamixel bus on {bus.port} (ids {', '.join(map(str, id_list))}, {baudrate} bd)",
                       bus.torque_line)


@app.command("rig")
@cli_errors
def rig(
    config_out: Path = typer.Option(..., "--config-out", help="Rig TOML to write, pointing at the emulated devices (for --hardware-config)."),
    probe: str = typer.Option("tee", "--probe", help="Probe preset or .toml (as for excite)."),
    sim_config: Optional[Path] = typer.Option(None, "--sim-config", help="Simulator TOML: the probe's physics behind the emulated devices."),
    seed: int = typer.Option(0, "--seed", help="Seed of the simulator's noise."),
    drop: float = typer.Option(0.0, "--drop", help="Fault: probability of losing each servo reply."),
    corrupt: float = typer.Option(0.0, "--corrupt", help="Fault: probability of a wrong CRC on each servo reply."),
    unplug_after: Optional[float] = typer.Option(None, "--unplug-after", help="Fault: the servo bus goes silent this many seconds after its first packet."),
    hardware_error: list[str] = typer.Option([], "--hardware-error", help="Fault: ID=overload or ID=overheating (repeatable)."),
    hardware_error_after: float = typer.Option(5.0, "--hardware-error-after", help="Seconds after the first packet."),
    missing: list[str] = typer.Option([], "--missing", help="Fault: a tracker sensor (tip or base) reported MISSING."),
    missing_after: float = typer.Option(0.0, "--missing-after", help="...from this many seconds after tracking starts (0: always)."),
    out_of_volume: list[str] = typer.Option([], "--out-of-volume", help="Fault: a tracker sensor (tip or base) out of the field generator's volume (port status bit 6; repeatable)..."),
    partly_out_of_volume: list[str] = typer.Option([], "--partly-out-of-volume", help="Fault: ...or partly out of it (bit 7)..."),
    out_of_volume_after: float = typer.Option(0.0, "--out-of-volume-after", help="...from this many seconds after tracking starts..."),
    out_of_volume_for: Optional[float] = typer.Option(None, "--out-of-volume-for", help="...for this many seconds (default: to the end)."),
    tracker_silent_after: Optional[float] = typer.Option(None, "--tracker-silent-after", help="Fault: the Aurora stops answering this many seconds after tracking starts, for good (its control unit lost power; 0: it never answers)."),
    stage: bool = typer.Option(False, "--stage", help="Also emulate the UDP translation/rotation stage (the probe follows it)."),
    stage_silent_after: Optional[float] = typer.Option(None, "--stage-silent-after", help="Fault: the stage stops answering this many seconds after its first request."),
) -> None:
    """The thesis rig, emulated: Dynamixel servos and an NDI Aurora whose sensors follow the
    simulated probe the knobs bend, so `endocal excite P --backend hardware --hardware-config
    RIG.toml` runs unchanged through the real SDKs. Runs until Ctrl-C or SIGTERM.
    """
    from endocal.emulate.rig import EmulatedRig
    from endocal.emulate.servos import BusFaults
    from endocal.emulate.stage import StageFaults
    from endocal.probe import load_probe
    from endocal.runs.format import check_parent
    from endocal.sim import SimConfig

    errors = _hardware_errors(hardware_error)
    aurora_faults = _aurora_faults(missing, missing_after, tracker_silent_after, out_of_volume, partly_out_of_volume,
                                   out_of_volume_after, out_of_volume_for, "--tracker-silent-after")
    check_parent(config_out)
    cfg = SimConfig.from_toml(sim_config) if sim_config is not None else None
    rig_ = EmulatedRig(load_probe(probe), cfg, seed=seed, on_event=_event,
                       bus_faults=BusFaults(drop_probability=drop, corrupt_probability=corrupt, unplug_after_s=unplug_after,
                                            hardware_error=errors, hardware_error_after_s=hardware_error_after),
                       aurora_faults=aurora_faults,
                       stage=stage, stage_faults=StageFaults(silent_after_s=stage_silent_after))
    rig_.start()
    rig_.write_config(config_out)
    where = f"stage on 127.0.0.1:{rig_.stage.port}" if rig_.stage is not None else "stage absent"
    _run_until_stopped(rig_, f"emulated rig: servos on {rig_.bus.port}, aurora on {rig_.aurora.port}, {where}; "
                             f"wrote {config_out}", rig_.bus.torque_line)


@app.command("aurora")
@cli_errors
def aurora(
    tip_port_handle: int = typer.Option(0x0A, "--tip-port-handle", help="Port handle of the tip sensor."),
    base_port_handle: int = typer.Option(0x0B, "--base-port-handle", help="Port handle of the base sensor."),
    missing: list[str] = typer.Option([], "--missing", help="Fault: report this sensor (tip or base) MISSING (repeatable)..."),
    missing_after: float = typer.Option(0.0, "--missing-after", help="...from this many seconds after TSTART (0: always)."),
    silent_after: Optional[float] = typer.Option(None, "--silent-after", help="Fault: stop answering this many seconds after TSTART, for good (the control unit lost power; 0: never answers)."),
    out_of_volume: list[str] = typer.Option([], "--out-of-volume", help="Fault: a sensor (tip or base) out of the field generator's volume (port status bit 6; repeatable)..."),
    partly_out_of_volume: list[str] = typer.Option([], "--partly-out-of-volume", help="Fault: ...or partly out of it (bit 7)..."),
    out_of_volume_after: float = typer.Option(0.0, "--out-of-volume-after", help="...from this many seconds after TSTART..."),
    out_of_volume_for: Optional[float] = typer.Option(None, "--out-of-volume-for", help="...for this many seconds (default: to the end)."),
) -> None:
    """An emulated NDI Aurora (System Control Unit) on a pseudo-terminal, in a process of its own.

    Serves a still tip 60 mm above the base; `endocal emulate rig` moves them with the knobs.
    Point `[tracker] serial_port` of a rig TOML at the printed path.
    """
    from endocal.emulate.aurora import AuroraEmulator

    emu = AuroraEmulator(tip_port_handle, base_port_handle,
                         faults=_aurora_faults(missing, missing_after, silent_after, out_of_volume, partly_out_of_volume,
                                               out_of_volume_after, out_of_volume_for))
    emu.start()
    _run_until_stopped(emu, f"aurora on {emu.port} (tip port handle {tip_port_handle:#04x}, "
                            f"base {base_port_handle:#04x}, 40 Hz)")


@app.command("stage")
@cli_errors
def stage(
    port: int = typer.Option(5005, "--port", help="UDP port on 127.0.0.1 (0: any free one)."),
    drop: float = typer.Option(0.0, "--drop", help="Fault: probability of losing each reply."),
    delay_ms: float = typer.Option(0.0, "--delay-ms", help="Fault: hold every reply back this long."),
    silent_after: Optional[float] = typer.Option(None, "--silent-after", help="Fault: stop answering this many seconds after the first request."),
    seed: int = typer.Option(0, "--seed", help="Seed of the lost replies."),
) -> None:
    """An emulated translation/rotation stage on loopback UDP (endocal's stage protocol, version 1).

    Point `[stage] host`/`port` of a rig TOML at the printed address, with mode = "udp".
    """
    from endocal.emulate.stage import StageEmulator, StageFaults

    emu = StageEmulator(port, faults=StageFaults(drop_probability=drop, silent_after_s=silent_after,
                                                 delay_s=delay_ms / 1000.0), seed=seed, on_event=_event)
    try:
        emu.start()
    except OSError as exc:
        from endocal.errors import ConfigError

        raise ConfigError(f"cannot listen on 127.0.0.1:{port} ({exc.strerror}): pick another --port") from None
    _run_until_stopped(emu, f"stage on 127.0.0.1:{emu.port} (UDP, stage protocol version 1)")
