"""Contact models, effect terms and rig dynamics: the one home of every formula labctl uses."""

from __future__ import annotations

from labctl.physics.catalogue import Roller, roller, rollers
from labctl.physics.contact import ContactModel
from labctl.physics.effects import (
    EFFECTS,
    ContactCase,
    Effect,
    EndEffects,
    MaterialHardness,
    Misalignment,
    SetupCompliance,
    SurfaceRoughness,
)
from labctl.physics.empirical import EQ5, EQ6, FITS, EmpiricalFit
from labctl.physics.hertz import HertzBallContact
from labctl.physics.law import BASELINES, ContactLaw, baseline_model
from labctl.physics.materials import Material, effective_modulus, material, materials
from labctl.physics.palmgren import PalmgrenContact
from labctl.physics.rating import static_load_rating_n
from labctl.physics.rig import RigModes, bounce_hz, rig_modes, roller_stiffness_from_bounce
from labctl.physics.rig_config import RigConfig, load_rig
from labctl.physics.tripp import TrippContact

__all__ = [
    "BASELINES", "EFFECTS", "EQ5", "EQ6", "FITS", "ContactCase", "ContactLaw", "ContactModel", "Effect",
    "EmpiricalFit", "EndEffects", "HertzBallContact", "Material", "MaterialHardness", "Misalignment",
    "PalmgrenContact", "RigConfig", "RigModes", "Roller", "SetupCompliance", "SurfaceRoughness",
    "TrippContact", "baseline_model", "bounce_hz", "effective_modulus", "load_rig", "material", "materials",
    "rig_modes", "roller", "roller_stiffness_from_bounce", "rollers", "static_load_rating_n",
]
