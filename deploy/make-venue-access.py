#!/usr/bin/env python3
"""The venue router's access control, its password file and every client's Zenoh config.

    /opt/reckon/venv/bin/python deploy/make-venue-access.py --venue /etc/reckon/venue.toml -o out/

writes, from the templates in deploy/zenoh/:
  out/router.json5            the router config with `access_control` for the venues given
  out/users.txt               the router's user:password file (existing passwords are kept)
  out/<venue>/hub.json5       the hub's client config, its credentials filled in
  out/<venue>/edge-<agent>.json5  one client config per agent, its credentials filled in

A venue is a venue file (every agent in it) or `NAME=AGENT,AGENT,...`. Zenoh's access control has
no per-user templates, so each agent gets its own rules; that is why this is generated.

What the rules allow (everything else is denied; a deny beats an allow):
- `hub.<venue>`: anything under `reckon/<venue>/**` (the hub, and `reckon record`/`reckon replay`
  run with the hub's credentials).
- `edge.<venue>.<agent>`: publish under `reckon/<venue>/<agent>/**` except the hub's outputs
  (`correction`, `field_map`, `pose/live`, `pose/refined`, `identity`); subscribe to its own
  `correction` and `field_map`;
  its liveliness token and flush queryable `reckon/<venue>/alive/edge/<agent>`; see the venue's
  other processes and ask them for flush barriers (`reckon/<venue>/alive/**`); learn which
  subscriptions the venue has (without them a client drops what it publishes).
- another router of the mesh, anything under `reckon/**`: `--peer-router USER` for one that dials
  this router (it logs in with that user name), `--dialed-router NAME` for one this router dials
  (it knows that one by its certificate: NAME is the common name make-certs.sh gave it).
"""

from __future__ import annotations

import argparse
import json
import os
import secrets
import sys
from pathlib import Path
from typing import Any

import json5

TEMPLATES = Path(__file__).resolve().parent / "zenoh"
HUB_OUTPUTS = ("correction", "field_map", "pose/live", "pose/refined", "identity")  # only the hub publishes these
EVERY_MESSAGE = ["put", "delete", "declare_subscriber", "query", "reply", "declare_queryable",
                 "liveliness_token", "declare_liveliness_subscriber", "liveliness_query"]
PASSWORD_BYTES = 18  # 24 url-safe characters: no ':' (the file's separator), no whitespace


def hub_user(venue: str) -> str:
    # '.' separates the parts because ids may contain '-' but never '.' (protocol.keys.check_id)
    return f"hub.{venue}"


def edge_user(venue: str, agent: str) -> str:
    return f"edge.{venue}.{agent}"


def _rule(rule_id: str, permission: str, flows: list[str], messages: list[str], key_exprs: list[str]) -> dict[str, Any]:
    return {"id": rule_id, "permission": permission, "flows": flows, "messages": messages, "key_exprs": key_exprs}


def _edge_rules(venue: str, agent: str) -> list[dict[str, Any]]:
    own, alive = f"reckon/{venue}/{agent}", f"reckon/{venue}/alive"
    user = edge_user(venue, agent)
    return [
        _rule(f"{user} publishes", "allow", ["ingress"], ["put", "delete"], [f"{own}/**"]),
        _rule(f"{user} not the hub's outputs", "deny", ["ingress"], ["put", "delete"],
              [f"{own}/{stream}" for stream in HUB_OUTPUTS]),
        _rule(f"{user} subscribes to its corrections", "allow", ["ingress"], ["declare_subscriber"],
              [f"{own}/correction", f"{own}/field_map"]),
        _rule(f"{user} receives its corrections", "allow", ["egress"], ["put"], [f"{own}/correction", f"{own}/field_map"]),
        _rule(f"{user} is alive", "allow", ["ingress"], ["liveliness_token", "declare_queryable", "reply"],
              [f"{alive}/edge/{agent}"]),
        # flush barriers (bus.flush) are queries on `alive/*/*`: a superset of the edge's own key,
        # so the egress rule must name the whole alive space for them to reach the edge's queryable
        _rule(f"{user} sees the venue's processes", "allow", ["ingress"],
              ["declare_liveliness_subscriber", "liveliness_query", "query"], [f"{alive}/**"]),
        _rule(f"{user} hears from the venue's processes", "allow", ["egress"],
              ["liveliness_token", "reply", "query"], [f"{alive}/**"]),
        # A client publishes only once the router has told it who subscribes (Zenoh's interest
        # replies): without these declarations an edge's first samples are silently dropped.
        # They are the venue's subscriptions, e.g. the hub's `reckon/<venue>/*/imu/*`, hence `**`.
        _rule(f"{user} learns who listens", "allow", ["egress"], ["declare_subscriber", "declare_queryable"],
              [f"reckon/{venue}/**"]),
    ]


def access_control(venues: dict[str, list[str]], peer_routers: list[str] = (),
                   dialed_routers: list[str] = ()) -> dict[str, Any]:
    """The router's `access_control` section: default deny, the rules above per venue and agent."""
    rules, subjects, policies = [], [], []

    def grant(user: str, granted: list[dict[str, Any]], match: str = "usernames") -> None:
        rules.extend(granted)
        subjects.append({"id": user, match: [user]})
        policies.append({"id": user, "rules": [rule["id"] for rule in granted], "subjects": [user]})

    for venue, agents in venues.items():
        grant(hub_user(venue), [_rule(f"{hub_user(venue)} owns the venue", "allow", ["ingress", "egress"],
                                      EVERY_MESSAGE, [f"reckon/{venue}/**"])])
        for agent in agents:
            grant(edge_user(venue, agent), _edge_rules(venue, agent))
    for user in peer_routers:
        grant(user, [_rule(f"{user} relays", "allow", ["ingress", "egress"], EVERY_MESSAGE, ["reckon/**"])])
    # A router this one dials presents no password (the dialler logs in, not the listener); it is
    # known by the certificate it showed, which this router checked against the venue CA.
    for name in dialed_routers:
        grant(name, [_rule(f"{name} relays", "allow", ["ingress", "egress"], EVERY_MESSAGE, ["reckon/**"])],
              match="cert_common_names")
    return {"enabled": True, "default_permission": "deny", "rules": rules, "subjects": subjects, "policies": policies}


def read_venue(spec: str) -> tuple[str, list[str]]:
    """`NAME=AGENT,...` or a venue file: (venue, agents). SystemExit naming the spec when it is wrong."""
    from protocol.keys import check_id
    from protocol.errors import ConfigError

    try:
        if "=" in spec:
            name, _, agents = spec.partition("=")
            return check_id(name, f"--venue {spec!r}"), [check_id(a, f"--venue {spec!r}") for a in agents.split(",")]
        from protocol.session import load_toml

        session = load_toml(Path(spec))
        return session.venue.name, [agent.id for agent in session.agents]
    except ConfigError as error:
        raise SystemExit(f"make-venue-access: {error}") from None


def read_users(path: Path) -> dict[str, str]:
    """An existing `user:password` file, so that re-running keeps every password already handed out."""
    if not path.exists():
        return {}
    users = {}
    for number, line in enumerate(path.read_text(encoding="utf-8").splitlines(), 1):
        if line.strip():
            user, colon, password = line.partition(":")
            if not colon or not user or not password:
                raise SystemExit(f"make-venue-access: {path} line {number}: expected user:password")
            users[user] = password
    return users


def _write(path: Path, text: str, mode: int = 0o640) -> None:
    """Write a file readable by its owner and group only: it holds passwords."""
    path.parent.mkdir(parents=True, exist_ok=True)
    descriptor = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, mode)
    with os.fdopen(descriptor, "w", encoding="utf-8") as out:
        out.write(text)
    os.chmod(path, mode)


def _client_config(template: Path, user: str, password: str) -> str:
    document = json5.loads(template.read_text(encoding="utf-8"))
    document["transport"]["auth"]["usrpwd"] = {"user": user, "password": password}
    return f"// generated by deploy/make-venue-access.py from {template.name}: edit that, then re-run\n" \
           + json.dumps(document, indent=2) + "\n"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--venue", action="append", required=True, metavar="VENUE.toml|NAME=AGENT,...")
    parser.add_argument("--peer-router", action="append", default=[], metavar="USER",
                        help="the username another router of the mesh connects with")
    parser.add_argument("--dialed-router", action="append", default=[], metavar="NAME",
                        help="the certificate name of a router of the mesh this one connects to")
    parser.add_argument("--templates", type=Path, default=TEMPLATES, help="router.json5, hub.json5, edge.json5")
    parser.add_argument("-o", "--output", type=Path, required=True, metavar="DIR")
    args = parser.parse_args(argv)

    venues = dict(read_venue(spec) for spec in args.venue)
    router = json5.loads((args.templates / "router.json5").read_text(encoding="utf-8"))
    router["access_control"] = access_control(venues, args.peer_router, args.dialed_router)
    _write(args.output / "router.json5",
           "// generated by deploy/make-venue-access.py from router.json5: edit that, then re-run\n"
           + json.dumps(router, indent=2) + "\n")

    users_path = args.output / "users.txt"
    users = read_users(users_path)
    clients = [(venue, "hub.json5", hub_user(venue)) for venue in venues]
    clients += [(venue, f"edge-{agent}.json5", edge_user(venue, agent)) for venue, agents in venues.items() for agent in agents]
    for user in [user for _, _, user in clients] + args.peer_router:
        users.setdefault(user, secrets.token_urlsafe(PASSWORD_BYTES))
    _write(users_path, "".join(f"{user}:{password}\n" for user, password in users.items()))
    for venue, name, user in clients:
        template = args.templates / ("hub.json5" if name == "hub.json5" else "edge.json5")
        _write(args.output / venue / name, _client_config(template, user, users[user]))
    print(f"wrote {args.output}/router.json5, users.txt and {len(clients)} client configs for "
          f"{', '.join(venues)}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
