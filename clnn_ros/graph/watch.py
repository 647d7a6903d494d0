"""What the trial manager reads in the ROS graph, judged without ROS: the names present in its
namespace and the publishers of the graph's topics. Who owns a process decides its death: run_all
and launch see the exit of the nodes they start, at once; the ROS graph is consulted only for
nodes someone else started (external_nodes). A participant that stops answering (a process
paused longer than the DDS lease) drops out of the ROS graph while alive, so its absence is no
death."""

from __future__ import annotations

import os
from collections import Counter

from .names import ENVIRONMENT, PUBLISHED_BY

# What rmw names a publisher whose participant's node list has not arrived yet (it comes apart
# from the endpoints, e.g. after a paused participant is rediscovered): asked again next time.
UNKNOWN_NODE = "_NODE_NAME_UNKNOWN_"


def named_twice(present: Counter, names: set[str]) -> list[str]:
    """The graph's node names that two nodes of the namespace carry."""
    return sorted(name for name in names if present[name] > 1)


def gone(seen: set[str], present: Counter, external: set[str]) -> list[str]:
    """The nodes started by someone else that were in the ROS graph and are not any more."""
    return sorted(name for name in seen & external if not present[name])


def foreign_publishers(publishers: dict[str, list[tuple[str, str]]],
                       namespace: str) -> list[tuple[str, str, str]]:
    """(topic, node, namespace) of each publisher on a graph topic that is not the node the
    graph has publish it (graph.names.PUBLISHED_BY) in this namespace: forged messages, or a
    second graph remapped onto this one's topics."""
    return [(topic, node, node_namespace)
            for topic, endpoints in sorted(publishers.items())
            for node, node_namespace in endpoints
            if (node, node_namespace) != (PUBLISHED_BY[topic], namespace) and
            node != UNKNOWN_NODE]


def describe_foreign(found: list[tuple[str, str, str]]) -> str:
    """The first foreign node found, with every graph topic it publishes on."""
    _, node, namespace = found[0]
    topics = sorted(topic for topic, *who in found if who == [node, namespace])
    return f"a foreign publisher on {', '.join(topics)}: node '{node}' in namespace {namespace}"


def names_pending(publishers: dict[str, list[tuple[str, str]]]) -> bool:
    """Whether a publisher on a graph topic has no node name yet (it comes after the endpoint)."""
    return any(node == UNKNOWN_NODE for endpoints in publishers.values() for node, _ in endpoints)


def renamed_environment(publishers: dict[str, list[tuple[str, str]]], namespace: str,
                        environment_present: bool) -> str | None:
    """With no node named environment in the namespace, another that publishes its topics: an
    environment node renamed (-r __node:=brain) that ran as the graph's was named a foreign
    publisher after a while, or a short run completed (issue 47); now the start waits for the
    environment by name, and this says why it never comes."""
    ours = [(topic, node, node_namespace) for topic, endpoints in sorted(publishers.items())
            if PUBLISHED_BY[topic] == ENVIRONMENT for node, node_namespace in endpoints]
    if environment_present or any(who == [ENVIRONMENT, namespace] for _, *who in ours):
        return None  # (the node list may lag behind the endpoints' names)
    strangers = [found for found in ours if found[1] != UNKNOWN_NODE]
    if not strangers:
        return None
    _, node, node_namespace = strangers[0]
    topics = sorted(topic for topic, *who in strangers if who == [node, node_namespace])
    return (f"no node named '{ENVIRONMENT}' in namespace {namespace}: node '{node}' (namespace "
            f"{node_namespace}) publishes {', '.join(topics)}; the graph takes an environment "
            f"node by its name (renamed, -r __node:={node}, it is none: docs/ENV_CONTRACT.md)")


WITHDRAWN = "withdrawn"


def graph_claim(started_ns: int, token: str) -> str:
    """A trial manager's claim to its namespace (graph.names.CLAIM): when it started (ns since
    the epoch) and a random token that tells apart two that started in the same nanosecond."""
    return f"{started_ns} {token}"


def withdrawal(claim: str) -> str:
    """What a trial manager says on CLAIM when its graph is over."""
    return f"{claim} {WITHDRAWN}"


def withdrawn_claim(text: str) -> str | None:
    """The claim a text on CLAIM withdraws, or None for a text that withdraws none."""
    claim, _, word = text.rpartition(" ")
    return claim if word == WITHDRAWN and claim_order(claim) is not None else None


def claim_order(claim: str) -> tuple[int, str] | None:
    """A claim as it orders: the earlier start first. Both trial managers of two graphs order
    their two claims alike (on two hosts a clock's skew may change which counts as first, never
    that exactly one is). None for a text that is no claim."""
    started, _, token = claim.partition(" ")
    return (int(started), token) if started.isdigit() and started.isascii() and token and \
        " " not in token else None


def another_graph(namespace: str, seen: str) -> str:
    """Why a graph gives way to another of the same names in its namespace and domain."""
    domain = os.environ.get("ROS_DOMAIN_ID", "") or "0"
    return (f"another graph runs in namespace {namespace} on ROS domain {domain}: {seen} (give "
            f"each graph its own --namespace or ROS_DOMAIN_ID)")
