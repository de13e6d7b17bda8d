"""Read a recording's stored blueprint back and evaluate each view's entity query with Rerun's rules
(https://rerun.io/docs/reference/entity-queries):
- an expression is `+ path` (or `path`) to include, `- path` to exclude; `$origin` is the view's
  space origin; a trailing `/**` matches the path and its whole subtree, and no other `*` is a
  wildcard (such a path matches only itself, literally);
- of the rules matching a path the most specific wins (longer path; an exact path beats the
  subtree of the same path); among equally specific ones the last wins; no match: excluded.
Only views reachable from the viewport's root container are shown, so only those are checked."""

from __future__ import annotations

import uuid
from collections import defaultdict
from dataclasses import dataclass
from pathlib import Path

from rerun.chunk import RrdReader

# what a view of each class can draw: components, by archetype prefix
DRAWS = {
    "TimeSeries": ("Scalars:",),
    "3D": ("Points3D:", "LineStrips3D:", "Ellipsoids3D:", "Arrows3D:", "Boxes3D:"),
    "2D": ("Points2D:", "LineStrips2D:", "Arrows2D:", "Boxes2D:"),
    "TextLog": ("TextLog:",),
}


@dataclass
class View:
    name: str
    kind: str
    origin: str
    query: list[str]


def _norm(p: str) -> str:
    return "/" + p.strip().strip("/")


def selects(view: View, entity: str) -> bool:
    """Rerun's rule for whether `entity` is in the view."""
    best: tuple[int, int, int] | None = None
    include = False
    for i, expr in enumerate(view.query):
        e = expr.strip()
        if not e:
            continue
        sign = e[0] if e[0] in "+-" else "+"
        path = e[1:].strip() if e[0] in "+-" else e
        path = path.replace("$origin", view.origin)
        subtree = path.endswith("/**")
        if subtree:
            path = path[:-3]
        path = _norm(path) if path.strip("/") else "/"
        if subtree:
            hit = path == "/" or entity == path or entity.startswith(path + "/")
        else:
            hit = entity == path
        if not hit:
            continue
        rank = (0 if path == "/" else path.count("/"), 0 if subtree else 1, i)
        if best is None or rank > best:
            best, include = rank, sign == "+"
    return include


def data_entities(path: Path) -> dict[str, set[str]]:
    """Entity path -> component columns, for entities with temporal rows in the recording."""
    out: dict[str, set[str]] = defaultdict(set)
    for ch in RrdReader(str(path)).stream():
        if ch.is_static:
            continue
        b = ch.to_record_batch()
        if b.num_rows:
            out[ch.entity_path].update(n for n in b.schema.names if ":" in n)
    return dict(out)


def last_blueprint_views(path: Path) -> list[View]:
    """The views reachable from the root container of the last blueprint stored in the file."""
    r = RrdReader(str(path))
    stores = r.blueprints()
    assert stores, f"{path}: no blueprint stored"
    # each send_blueprint is a store of its own, activated when it arrives: the newest one is
    # shown. Row ids (TUIDs) grow with the time of logging, so the newest store has the largest.
    chunks = {s.recording_id: list(r.stream(store=s)) for s in stores}

    def newest_row(store: str) -> bytes:
        ids = [x for ch in chunks[store] for x in ch.to_record_batch().column(0).to_pylist()]
        return max(ids)

    newest = max(chunks, key=newest_row)
    last: dict[str, dict[str, list]] = defaultdict(dict)
    for ch in chunks[newest]:
        b = ch.to_record_batch()
        for name in b.schema.names:
            if ":" in name:
                vals = [v for v in b.column(name).to_pylist() if v is not None]
                if vals:
                    last[ch.entity_path][name] = vals[-1]
    root = "container/" + str(uuid.UUID(bytes=bytes(last["/viewport"]["ViewportBlueprint:root_container"][0])))
    views: list[View] = []
    stack = [root]
    while stack:
        node = stack.pop()
        ent = _norm(node)
        if ent.startswith("/container/"):
            stack.extend(reversed(last[ent].get("ContainerBlueprint:contents", [])))
            continue
        v = last[ent]
        q = last.get(ent + "/ViewContents", {}).get("ViewContents:query", ["$origin/**"])
        views.append(View(v["ViewBlueprint:display_name"][0], v["ViewBlueprint:class_identifier"][0],
                          _norm(v["ViewBlueprint:space_origin"][0]), list(q)))
    return views


def empty_views(path: Path) -> list[str]:
    """Names of the shown views that select no entity holding data they can draw."""
    data = data_entities(path)
    bad = []
    for v in last_blueprint_views(path):
        draws = DRAWS.get(v.kind, ())
        if not any(selects(v, e) and any(c.startswith(draws) for c in comps) for e, comps in data.items()):
            bad.append(f"{v.name} ({v.kind}, origin {v.origin}, query {v.query})")
    return bad
