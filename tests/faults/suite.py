"""Which probes the suite runs (the worker asks for the in-process ones by name)."""

from __future__ import annotations

from faults import capi, cli, live, readers
from faults.corpus import Corpus
from faults.framework import Api, Cli


def api_probes(corpus: Corpus) -> list[Api]:
    return readers.probes(corpus) + live.probes(corpus) + capi.probes(corpus)


def cli_probes(corpus: Corpus) -> list[Cli]:
    return cli.probes(corpus)
