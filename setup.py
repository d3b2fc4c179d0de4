"""Build hook: ship the top-level ``scenes/`` and ``assets/`` folders inside the wheel.

In a source checkout they live at the repository root (where MJCF authors expect them); in a wheel they are
copied to ``embodied_adhoc/_data/``. ``embodied_adhoc.paths`` resolves both layouts.
"""

import shutil
from pathlib import Path

from setuptools import setup
from setuptools.command.build_py import build_py

ROOT = Path(__file__).parent
SHIPPED = ("scenes", "assets")


class BuildWithData(build_py):
    def run(self):
        super().run()
        for name in SHIPPED:
            source = ROOT / name
            if source.is_dir():
                target = Path(self.build_lib) / "embodied_adhoc" / "_data" / name
                if target.exists():
                    shutil.rmtree(target)
                shutil.copytree(source, target)


setup(cmdclass={"build_py": BuildWithData})
