"""The out-of-tree plugins of ``tests/plugins/`` (the pendulum model of docs/models.md, the
rangefinder sensor of docs/sensors.md) installed the way a package installs them: a temporary
directory holding a distribution's metadata with its entry points and a Hydra search-path plugin
for ``tests/plugins/conf``, put on ``PYTHONPATH`` (or ``sys.path``) with ``tests/plugins``. The
test environment itself is not modified."""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

PLUGINS = Path(__file__).resolve().parent / "plugins"
DOCS = Path(__file__).resolve().parents[1] / "docs"

SEARCH_PATH_PLUGIN = """\
from hydra.core.config_search_path import ConfigSearchPath
from hydra.plugins.search_path_plugin import SearchPathPlugin


class TestPluginsSearchPath(SearchPathPlugin):
    def manipulate_search_path(self, search_path: ConfigSearchPath) -> None:
        search_path.append(provider="quadest-test-plugins", path={path!r})
"""


def fake_site(site: Path, entry_points: str, name: str = "quadest-test-plugins", conf: Path | None = PLUGINS / "conf"):
    """Write a distribution ``name`` with ``entry_points`` (the text of its ``entry_points.txt``)
    into ``site``; with ``conf``, also a Hydra search-path plugin that appends that folder."""
    info = site / f"{name.replace('-', '_')}-0.1.dist-info"
    info.mkdir(parents=True)
    (info / "METADATA").write_text(f"Metadata-Version: 2.1\nName: {name}\nVersion: 0.1\n")
    (info / "entry_points.txt").write_text(entry_points)
    if conf is not None:
        plugin = site / "hydra_plugins" / f"{name.replace('-', '_')}_searchpath"
        plugin.mkdir(parents=True)
        (plugin / "__init__.py").write_text(SEARCH_PATH_PLUGIN.format(path=f"file://{conf}"))
    return site


def quadest(args: list[str], cwd: Path, site: Path) -> subprocess.CompletedProcess:
    """``quadest ARGS`` in a subprocess that sees the plugins of ``site`` and ``tests/plugins``."""
    path = [str(site), str(PLUGINS), os.environ.get("PYTHONPATH", "")]
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(path)}
    return subprocess.run(
        [sys.executable, "-m", "quadest.app.cli", *args], cwd=cwd, env=env, capture_output=True, text=True, timeout=600
    )


def fenced_blocks(page: str) -> list[str]:
    """The contents of the fenced code blocks of ``docs/<page>``."""
    text = (DOCS / page).read_text(encoding="utf-8")
    return [m.group(1) for m in re.finditer(r"^```[a-z]*\n(.*?)^```$", text, flags=re.MULTILINE | re.DOTALL)]
