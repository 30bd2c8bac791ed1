"""Where the Hydra config tree is.

The configs live in the repository's top-level ``conf/`` and are copied into the wheel as
``quadest/conf``. Hydra needs an absolute directory for a console script (a relative
``config_path`` fails for wheel and editable installs alike, docs/sources.md),
so it is computed here: the packaged copy first, the repository's ``conf/`` second.
"""

from __future__ import annotations

from pathlib import Path

_PACKAGE = Path(__file__).resolve().parents[1]


def config_dir() -> str:
    """Absolute path of the primary config directory."""
    for candidate in (_PACKAGE / "conf", _PACKAGE.parents[1] / "conf"):
        if (candidate / "config.yaml").is_file():
            return str(candidate)
    raise FileNotFoundError(
        f"quadest configs not found: looked for config.yaml in {_PACKAGE / 'conf'} and "
        f"{_PACKAGE.parents[1] / 'conf'}; reinstall the package"
    )
