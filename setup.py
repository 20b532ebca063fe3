"""Package discovery of the skelagnostic distribution; everything else is in pyproject.toml.

The Hydra config tree lives in the top-level ``conf/`` directory but is installed as
the ``skelagnostic.conf`` package (``pkg://skelagnostic.conf``), so that ``pip install .``,
``pip install -e .`` and a wheel all give a CLI that works from any directory.
``pyproject.toml`` cannot say "discover the packages under these roots *and* add
``skelagnostic.conf`` from ``conf/``": ``[tool.setuptools.packages]`` is either a fixed
list or a ``find`` directive, and ``find`` cannot rename a directory. So the packages
and their ``package_dir`` mapping are computed here.
"""

from __future__ import annotations

from setuptools import find_namespace_packages, setup

#: Source roots: the framework and the built-in method plugins.
ROOTS = ("src", "plugins/humot/src", "plugins/pcmrl/src", "plugins/vqpae/src")
#: The config tree and the package it is installed as.
CONF_DIR, CONF_PACKAGE = "conf", "skelagnostic.conf"

packages: list[str] = []
package_dir: dict[str, str] = {}
for root in ROOTS:
    for package in find_namespace_packages(root):
        packages.append(package)
        if "." not in package:
            package_dir[package] = f"{root}/{package}"
packages.append(CONF_PACKAGE)
package_dir[CONF_PACKAGE] = CONF_DIR

setup(packages=packages, package_dir=package_dir)
