"""Systems of RT components: a system file names RTC profiles, their contexts,
configuration sets and port connections; :func:`run_system_file` runs them all.

docs/rtc.md §14 describes the file and the run."""

from .build import PreparedComponent, PreparedSystem, blocking_cycle, prepare_system
from .loader import is_system_file, load_system, loads_rtsys, loads_system_yaml
from .model import (
    ComponentSpec,
    ContextSpec,
    DataConnectionSpec,
    PortRef,
    ServiceConnectionSpec,
    SystemFileError,
    SystemSpec,
)
from .run import (
    ComponentReport,
    ConnectorReport,
    SystemSummary,
    run_system,
    run_system_cli,
    run_system_file,
)

__all__ = [
    "ComponentReport",
    "ComponentSpec",
    "ConnectorReport",
    "ContextSpec",
    "DataConnectionSpec",
    "PortRef",
    "PreparedComponent",
    "PreparedSystem",
    "ServiceConnectionSpec",
    "SystemFileError",
    "SystemSpec",
    "SystemSummary",
    "blocking_cycle",
    "is_system_file",
    "load_system",
    "loads_rtsys",
    "loads_system_yaml",
    "prepare_system",
    "run_system",
    "run_system_cli",
    "run_system_file",
]
