"""Adds the package's configs (``estimator/iekf.yaml``) to Hydra's search path. Hydra imports
every ``hydra_plugins.*`` module at start-up, so this stays tiny."""

from hydra.core.config_search_path import ConfigSearchPath
from hydra.plugins.search_path_plugin import SearchPathPlugin


class QuadestIEKFSearchPathPlugin(SearchPathPlugin):
    def manipulate_search_path(self, search_path: ConfigSearchPath) -> None:
        search_path.append(provider="quadest-iekf", path="pkg://quadest_iekf.conf")
