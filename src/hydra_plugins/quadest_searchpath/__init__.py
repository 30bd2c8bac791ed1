"""Puts quadest's config tree on Hydra's search path, so that primary configs elsewhere (the sweep
experiments, ``experiments/NAME.yaml``, which ``quadest experiment=NAME`` makes the primary config)
can use its groups. Hydra imports every ``hydra_plugins.*`` module at start-up: keep this light."""

from hydra.core.config_search_path import ConfigSearchPath
from hydra.plugins.search_path_plugin import SearchPathPlugin


class QuadestSearchPathPlugin(SearchPathPlugin):
    def manipulate_search_path(self, search_path: ConfigSearchPath) -> None:
        from quadest.config.paths import config_dir

        search_path.append(provider="quadest", path=f"file://{config_dir()}")
