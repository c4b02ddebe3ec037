"""The one exception tree of adaptune.

Library code raises these; only the CLI (``stages.cli``) turns them into one line on
stderr and exit code 1. Messages name the file or value and the rule it breaks.
"""

from __future__ import annotations


class AdaptuneError(Exception):
    """Root of every error adaptune raises on purpose. Its message is one line: line breaks
    of a wrapped library message (a YAML or Parquet parser's) become spaces."""

    def __str__(self) -> str:
        return " ".join(line.strip() for line in super().__str__().splitlines() if line.strip())


class ConfigError(AdaptuneError):
    """A params.yaml section or a CLI option breaks a rule."""


class InputError(AdaptuneError):
    """An input file (scans, poses, bag, MCAP, Parquet) is missing, malformed or inconsistent."""


class OutputError(AdaptuneError):
    """An output path cannot be written: empty, a folder, a file in the way of its folder, no
    permission, a full disk; or it names one of the command's own inputs."""


class SchemaError(InputError):
    """A file follows another schema or schema version than the one expected."""


class OdometryError(AdaptuneError):
    """An odometry run failed (raised, diverged, returned NaN, lost frames, timed out)."""


# N818 (Error suffix) is waived: TrialTimeout is public API, raised and caught across the
# package and by code in progress; a rename (or alias) would change it and its __name__.
class TrialTimeout(OdometryError):  # noqa: N818
    """An odometry run outlived its time limit."""


class InfrastructureError(AdaptuneError):
    """The machinery around an odometry run failed, not the odometry: a trial process killed by
    a signal from outside (the OOM killer's SIGKILL), a broken executor, a lost worker. The
    trial is retried; it is never scored."""


class ArtifactError(AdaptuneError):
    """A model artifact is missing files, tampered with, or made for something else."""


class QueryError(AdaptuneError):
    """A SQL query against the results database failed."""
