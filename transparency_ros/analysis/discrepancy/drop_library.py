"""The drop test's candidate effects, as one library: which are searched for depends on what the
recordings show (a drive's clip, a shuttle's bounce, recorded torques)."""

from __future__ import annotations

from transparency_ros.analysis.discrepancy.drop_bounce import Bounces
from transparency_ros.analysis.discrepancy.drop_clip import DriveClip
from transparency_ros.analysis.discrepancy.drop_cogging import DropCogging
from transparency_ros.analysis.discrepancy.drop_effects import (
    DeclaredWeight,
    DropBacklash,
    DropDrift,
    DropEffect,
    DropOffset,
    DropQuantization,
    DropRestitution,
    DropStiction,
    HubArmCompliance,
    ImpactSpeedLoss,
    MeasuredSaturation,
    SensorDelay,
    SetPhysics,
    ShownRestitution,
    StructuralCompliance,
)


def drop_library(
    shuttle_mass_kg: float,
    coulomb_nm: float,
    loaded_inertia_kgm2: float,
    sample_interval_s: float,
    *,
    noise_floor_rad: float = 0.0,
    encoder_count_rad: float = 0.0,
    torques_recorded: bool = False,
    clip: DriveClip | None = None,
    bounces: Bounces | None = None,
) -> list[DropEffect]:
    """The candidates (``loaded_inertia_kgm2``: the arm's with the shuttle on it, J_a + m r^2,
    for the frequency a torsional compliance is reported at; ``sample_interval_s``: between
    the encoder's readings; ``noise_floor_rad``: the RMS position error sensor noise alone
    gives, and ``encoder_count_rad``: one count of the encoder, the larger of them the
    narrowest backlash named). A drive's limit is read off its recorded torque
    where it shows one (``clip``); where every trial recorded the drive's torque and none
    shows a clip, no limit is searched for (the torque would show it); where torques are
    missing, it is fitted. A rebound is named where the load cell shows one (``bounces``),
    searched for where it shows the shuttle leave the arm without striking it again within
    the recording, and not searched for where it never leaves the arm (without
    ``bounces``: searched for)."""
    rebound: list[DropEffect] = []
    hub = HubArmCompliance(loaded_inertia_kgm2)
    if bounces is not None and bounces.shown:
        rebound = [ShownRestitution(bounces, rival=hub)]
    elif bounces is None or bounces.possible:
        rebound = [DropRestitution()]
    if clip is not None:
        saturation: list[DropEffect] = [MeasuredSaturation(clip)]
    elif torques_recorded:
        saturation = []
    else:
        # the drive clips its impedance torque (a current limit); the offset is added after it
        saturation = [
            SetPhysics("torque_saturation", "limit_nm", 0.02, 3.0, "torque_limit_nm", null=None)
        ]
    least_band = max(noise_floor_rad, encoder_count_rad)
    return [
        DropDrift(),
        DropOffset(coulomb_nm),
        DeclaredWeight(),
        DropStiction(),
        *rebound,
        ImpactSpeedLoss(shuttle_mass_kg),
        StructuralCompliance(),
        hub,
        DropBacklash(least_rad=least_band),
        DropBacklash(start=1.0, least_rad=least_band),
        SensorDelay(sample_interval_s),
        DropQuantization(),
        *saturation,
        DropCogging(),
    ]
