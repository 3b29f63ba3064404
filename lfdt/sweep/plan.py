"""Split the pipeline's DAG into what a sweep builds once, the independent chains it fans out, and what it ends with.

A *chain* is a connected group of the matrix stages whose matrix is a sweep parameter (``${grid.…}`` or
``${twin.tasks}`` in dvc.yaml): for one demo count, a translator method with the BC training and evaluation that
use it (``lfdt_track`` joins the ``lfdt`` chain whose translations it re-executes), or the whole twin of one task.
Chains share nothing but their upstream stages, so they can run on different machines. Everything upstream of a
chain (experts, random motion, demonstrations, the dynamics model) is *shared*: built once by the coordinator and
restored from DVC's run cache in every chain. The rest (the reports) is *final*: run by the coordinator after the
chains.
"""

from __future__ import annotations

import contextlib
from dataclasses import dataclass
from pathlib import Path

import networkx as nx
import yaml

FAN_OUT_PARAMS = ("${grid.", "${twin.tasks}")
"""A matrix over one of these params makes a stage family fan out (one chain per matrix item)."""


@dataclass(frozen=True)
class Plan:
    """Which stages run where, each tuple in an order DVC could run them in (upstream first)."""

    shared: tuple[str, ...]
    """Built once by the coordinator before the chains."""
    chains: dict[str, tuple[str, ...]]
    """Chain name (its first stage) -> its stages."""
    final: tuple[str, ...]
    """Run by the coordinator after the chains: every stage that is neither shared nor in a chain."""


def fan_out_families(dvc_yaml: str | Path) -> set[str]:
    """The stage families of dvc.yaml whose matrix is a sweep parameter."""
    stages = (yaml.safe_load(Path(dvc_yaml).read_text()) or {}).get("stages") or {}
    return {name for name, st in stages.items()
            if isinstance(st, dict) and isinstance(st.get("matrix"), dict)
            and any(tok in str(v) for v in st["matrix"].values() for tok in FAN_OUT_PARAMS)}


def upstream_graph(root: str | Path) -> nx.DiGraph:
    """Stage names of the DVC project at ``root``, with an edge from each stage to every stage it depends on."""
    from dvc.repo import Repo

    # DVC resolves some paths against the working directory: build the graph from inside the project
    with contextlib.chdir(root), Repo(str(root)) as repo:
        g = repo.index.graph
        out = nx.DiGraph()
        out.add_nodes_from(s.addressing for s in g.nodes)
        out.add_edges_from((a.addressing, b.addressing) for a, b in g.edges)
    return out


def _lexi_upstream_first(g: nx.DiGraph) -> list[str]:
    """The stages of ``g`` upstream first, ties broken by name (the same order on every machine)."""
    return list(nx.lexicographical_topological_sort(g.reverse(copy=True)))


def make_plan(root: str | Path) -> Plan:
    """The sweep plan of the DVC project at ``root`` with its current params."""
    root = Path(root)
    g = upstream_graph(root)
    families = fan_out_families(root / "dvc.yaml")
    in_chain = {n for n in g if n.split("@", 1)[0] in families}
    chains: dict[str, tuple[str, ...]] = {}
    for comp in nx.connected_components(g.subgraph(in_chain).to_undirected()):
        order = tuple(_lexi_upstream_first(g.subgraph(comp)))
        chains[order[0]] = order
    shared = set().union(*(nx.descendants(g, n) for n in in_chain)) - in_chain if in_chain else set()
    final = set(g) - in_chain - shared
    return Plan(shared=tuple(_lexi_upstream_first(g.subgraph(shared))), chains=dict(sorted(chains.items())),
                final=tuple(_lexi_upstream_first(g.subgraph(final))))
