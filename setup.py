"""Package discovery: labctl and drivers, plus the top-level protocols/ folder shipped as ``labctl.protocols``."""

from setuptools import find_packages, setup

setup(
    packages=[*find_packages(include=["labctl", "labctl.*", "drivers", "drivers.*"]), "labctl.protocols"],
    package_dir={"labctl.protocols": "protocols"},
)
