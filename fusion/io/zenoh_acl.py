"""Zenoh access control for fusion: roles of [zenoh.access_control] turned into zenoh's rules.

Zenoh checks every message that crosses a link of the node whose configuration holds the rules
(the service's peer, or a router), against the identity of the other end: here the common name
of its TLS client certificate. The default is deny, in both directions, so each role lists what
it may send to the node (ingress) and what the node may forward to it (egress). A rule key
allows a message when the rule key includes the message's key (`meas/*` includes `meas/cam1`,
`meas/cam1` does not include `meas/*`). The node's own session is never filtered: the service
on its peer publishes and answers without a rule.

With NS the namespace, what each role may do (everything else is dropped):

  sensor X      put fusion/NS/meas/X; see the service's subscription on fusion/NS/meas/*
                (declare_subscriber, egress) so its publisher matches; and what zenoh's
                advanced publisher needs under fusion/NS/meas/X/@adv/pub/** (its token, cache
                queryable and heartbeats in, the service's history and recovery queries out
                (those also on fusion/NS/meas/*/@adv/*/**), their replies in) and to see the
                service's subscriber token
                (fusion/NS/meas/*/@adv/sub/**: the token out, the liveliness query for it in)
  input X       the same for a control source, on fusion/NS/input/X (subscribed: input/*)
  simulator     put fusion/NS/meas/*, fusion/NS/input/* and fusion/NS/truth/*; see
                subscriptions on them; the advanced publisher's exchanges as for a sensor, on
                fusion/NS/meas/* and fusion/NS/input/*
  consumer      subscribe fusion/NS/tracks/* and receive its puts; query fusion/NS/status and
                fusion/NS/snapshot and receive the replies
  recorder      subscribe fusion/NS/meas/*, input/* and truth/* and receive their puts; what
                zenoh's advanced subscriber needs on meas/* and input/* (its token in, the
                publishers' tokens and heartbeats out, its history and recovery queries in
                and their replies out): it recovers a dropped sample as the service does
  service       put fusion/NS/tracks/* and see the subscriptions on it (its declared publishers
                only send to subscribers they know of); declare the status and snapshot
                queryables, receive the queries on them and reply; subscribe measurements,
                inputs and truth and receive their puts, with the advanced subscriber's
                exchanges as a recorder's (for rules on a router the service connects to)

Hence a sensor cannot forge estimates (its put on tracks is dropped at ingress), cannot answer
for the service (its status or snapshot queryable is never declared to the node, so no query
reaches it), cannot read the snapshot, and cannot speak for another sensor (nor a control
source for another source); a consumer cannot publish measurements or inputs.
"""

from __future__ import annotations

from typing import Any

from fusion.config import AccessControlConfig, TrackerConfig

PUT, SUB, QUERY, REPLY, QUERYABLE = "put", "declare_subscriber", "query", "reply", "declare_queryable"
TOKEN, LIVE_QUERY, LIVE_SUB = "liveliness_token", "liveliness_query", "declare_liveliness_subscriber"
IN, OUT = "ingress", "egress"


def _keys(ns: str) -> dict[str, str]:
    root = f"fusion/{ns}"
    return {"meas": f"{root}/meas/*", "input": f"{root}/input/*", "truth": f"{root}/truth/*",
            "tracks": f"{root}/tracks/*", "status": f"{root}/status", "snapshot": f"{root}/snapshot"}


def role_grants(role: str, ns: str, *, sensor_id: str = "") -> list[tuple[str, str, list[str]]]:
    """What `role` may do: (message, flow, key expressions) triples, all "allow". `sensor_id`:
    the sensor's id for "sensor", the control source's for "input"."""
    k = _keys(ns)
    queries = [k["status"], k["snapshot"]]
    samples = [k["meas"], k["input"], k["truth"]]  # what the service takes in
    if role in ("sensor", "input"):
        kind = "meas" if role == "sensor" else "input"
        own = [f"fusion/{ns}/{kind}/{sensor_id}"]
        return [(PUT, IN, own), (SUB, OUT, [k[kind]]), *_recoverable_publisher(own, k[kind])]
    if role == "simulator":
        return [(PUT, IN, samples), (SUB, OUT, samples),
                *_recoverable_publisher([k["meas"]], k["meas"]), *_recoverable_publisher([k["input"]], k["input"])]
    if role == "consumer":
        return [(SUB, IN, [k["tracks"]]), (PUT, OUT, [k["tracks"]]), (QUERY, IN, queries), (REPLY, OUT, queries)]
    if role == "recorder":
        return [(SUB, IN, samples), (PUT, OUT, samples), *_recovering_subscriber([k["meas"], k["input"]])]
    if role == "service":
        return [(PUT, IN, [k["tracks"]]), (SUB, OUT, [k["tracks"]]), (QUERYABLE, IN, queries),
                (REPLY, IN, queries), (SUB, IN, samples), (PUT, OUT, samples), (QUERY, OUT, queries),
                *_recovering_subscriber([k["meas"], k["input"]])]
    raise ValueError(f"unknown role {role!r}")


def _recoverable_publisher(own: list[str], subscribed: str) -> list[tuple[str, str, list[str]]]:
    """What zenoh's advanced publisher on the keys `own` (fusion.io.zenoh_advanced) exchanges
    with the service's advanced subscriber on `subscribed`: its liveliness token and cache
    queryable under `<key>/@adv/pub/**` in, heartbeats in, history and recovery queries out and
    their replies in; the subscriber's token (`<subscribed>/@adv/sub/**`) out, and the query
    for it in (the publisher waits for it)."""
    adv_pub = [f"{key}/@adv/pub/**" for key in own]
    adv_sub = [f"{subscribed}/@adv/sub/**"]
    # the recovery of a hole asks <subscribed>/@adv/*/<zid>/<eid>/**: only the publisher with
    # that id has a queryable there, so the query reaches no other sensor's cache
    recovery = [f"{subscribed}/@adv/*/**"]
    return [(TOKEN, IN, adv_pub), (QUERYABLE, IN, adv_pub), (PUT, IN, adv_pub), (QUERY, OUT, [*adv_pub, *recovery]),
            (REPLY, IN, [*own, *adv_pub]), (SUB, OUT, [f"{subscribed}/@adv/pub/**"]),
            (TOKEN, OUT, adv_sub), (LIVE_QUERY, IN, [f"{key}/@adv/sub/**" for key in own])]


def _recovering_subscriber(subscribed: list[str]) -> list[tuple[str, str, list[str]]]:
    """What zenoh's advanced subscriber on each key of `subscribed` (fusion.io.zenoh_advanced's
    RecoveringSubscription) exchanges with the publishers' side of _recoverable_publisher: its
    own liveliness token (`<key>/@adv/sub/**`) in; its liveliness subscriber on the publishers'
    tokens (`<key>/@adv/pub/**`, with the liveliness query for those already there) in and the
    tokens out; its subscription to their heartbeats in and the heartbeats out; its history and
    recovery queries (under `<key>/@adv/*/**`: the publishers' caches) in and their replies, on
    the samples' keys, out."""
    adv_pub = [f"{key}/@adv/pub/**" for key in subscribed]
    return [(TOKEN, IN, [f"{key}/@adv/sub/**" for key in subscribed]), (LIVE_SUB, IN, adv_pub),
            (LIVE_QUERY, IN, adv_pub), (TOKEN, OUT, adv_pub), (SUB, IN, adv_pub), (PUT, OUT, adv_pub),
            (QUERY, IN, [f"{key}/@adv/*/**" for key in subscribed]), (REPLY, OUT, [*subscribed, *adv_pub])]


def access_control_section(ac: AccessControlConfig, *, namespace: str) -> dict[str, Any]:
    """Zenoh's `access_control` configuration section (a JSON-able dict) for `ac` on `namespace`:
    default deny; one subject, one policy and its rules per role (per sensor for sensors, per
    source for control sources); roles with no names are left out."""
    groups: list[tuple[str, str, str, list[str]]] = [  # (id, role, sensor or source id, common names)
        *((f"sensor-{sid}", "sensor", sid, names) for sid, names in sorted(ac.sensors.items())),
        *((f"input-{sid}", "input", sid, names) for sid, names in sorted(ac.inputs.items())),
    ]
    groups += [(role, role, "", names) for role, names in (
        ("simulator", ac.simulators), ("consumer", ac.consumers), ("recorder", ac.recorders),
        ("service", ac.services))]
    rules: list[dict[str, Any]] = []
    subjects: list[dict[str, Any]] = []
    policies: list[dict[str, Any]] = []
    for gid, role, sid, names in groups:
        if not names:
            continue
        ids = []
        for n, (message, flow, keys) in enumerate(role_grants(role, namespace, sensor_id=sid)):
            ids.append(f"{gid}-{n}")
            rules.append({"id": ids[-1], "messages": [message], "flows": [flow], "permission": "allow",
                          "key_exprs": keys})
        subjects.append({"id": gid, "cert_common_names": sorted(set(names))})
        policies.append({"id": gid, "rules": ids, "subjects": [gid]})
    return {"enabled": True, "default_permission": "deny", "rules": rules, "subjects": subjects,
            "policies": policies}


def mismatches(ac: AccessControlConfig | None, tracker: TrackerConfig) -> list[str]:
    """What in [zenoh.access_control] (`ac`) does not meet the tracker, in words (none: they meet): a
    grant for a sensor id or control source the tracker does not have (the service ignores what
    comes there: a typo leaves the real one without a grant, and zenoh drops its samples without
    a word; or it is meant for a recorder alone), and a sensor or control source of the tracker
    that nobody may put, no simulator being named either."""
    if ac is None:
        return []
    sensors = sorted(s.id for s in tracker.sensors)
    source = None if tracker.control is None else tracker.control.source_id
    out = [f"zenoh.access_control.sensors grants {sid!r}, which is not a sensor of [tracker] (its sensors: "
           f"{', '.join(sensors)}): the service ignores its measurements" for sid in sorted(ac.sensors)
           if sid not in sensors]
    out += [f"zenoh.access_control.inputs grants {sid!r}, which is not the tracker's control source ("
            + ("it has none" if source is None else f"{source!r}") + "): the service ignores its inputs"
            for sid in sorted(ac.inputs) if sid != source]
    if not ac.simulators:
        out += [f"sensor {sid!r} has no grant in zenoh.access_control.sensors and no simulators are named: "
                "nothing may put its measurements" for sid in sensors if sid not in ac.sensors]
        if source is not None and source not in ac.inputs:
            out.append(f"control source {source!r} has no grant in zenoh.access_control.inputs and no simulators are "
                       "named: nothing may put its inputs")
    return out
