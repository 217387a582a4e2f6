"""A robot computer turned hostile, for the security tests, run as its own process:
``python tests/acl_attacker.py CONFIG.json5 PLAN.json``. With robot I's configuration
it tries everything the plan lists that robot I must not do, each before the
control (something it may do) that shows the attempt would have been seen:

1. it subscribes (keys and wildcards), watches tokens and declares queryables, then
   prints ``ready``; the test puts on every key, control last, until this process has
   heard the control ``CONTROL_ROUNDS`` times and prints ``heard``;
2. on ``go`` (stdin) it holds tokens, puts and deletes on forbidden keys and queries,
   then puts its own keys (the control) and holds its own token, prints a JSON report
   of what it heard, was answered and was asked, and ``done``;
3. it stays connected until ``bye`` (stdin), so that the test can query it.

Its payloads start with ``attacker`` so that the test tells them from its own.
Exit 3 if the session cannot open."""

from __future__ import annotations

import json
import sys
import threading
import time

import zenoh

CONTROL_ROUNDS = 5
MARK = b"attacker"


def main() -> int:
    config, plan_file = sys.argv[1], sys.argv[2]
    plan = json.loads(open(plan_file).read())
    try:
        session = zenoh.open(zenoh.Config.from_file(config))
    except Exception as exc:
        print(f"cannot open: {exc}", flush=True)
        return 3
    lock = threading.Lock()
    heard: dict[str, int] = {}
    tokens_seen: set[str] = set()
    asked: list[str] = []

    def on_sample(sample: zenoh.Sample) -> None:
        with lock:
            key = str(sample.key_expr)
            heard[key] = heard.get(key, 0) + 1

    def on_token(sample: zenoh.Sample) -> None:
        if sample.kind == zenoh.SampleKind.PUT:
            with lock:
                tokens_seen.add(str(sample.key_expr))

    def on_query(query: zenoh.Query) -> None:
        with lock:
            asked.append(str(query.key_expr))
        query.reply(query.key_expr, MARK + b" answer")

    remote = zenoh.Locality.REMOTE  # what crosses the router, not its own puts and gets
    keep = [session.declare_subscriber(k, on_sample, allowed_origin=remote)
            for k in plan["subscribe"] + plan["may_subscribe"]]
    keep += [session.liveliness().declare_subscriber(k, on_token, history=True)
             for k in plan["watch"] + plan["may_watch"]]
    keep += [session.declare_queryable(k, on_query, allowed_origin=remote)
             for k in plan["answer"]]
    control = plan["control_hear"]
    keep.append(session.declare_subscriber(control, on_sample, allowed_origin=remote))
    print("ready", flush=True)
    while True:
        with lock:
            if heard.get(control, 0) >= CONTROL_ROUNDS:
                break
        time.sleep(0.01)
    with lock:  # before it holds tokens of its own, which it would see itself
        seen = sorted(tokens_seen)
    print("heard", flush=True)
    if sys.stdin.readline().strip() != "go":
        return 1
    keep += [session.liveliness().declare_token(k) for k in plan["tokens"]]
    for k in plan["put"]:
        session.put(k, MARK + b" put")
    for k in plan["delete"]:
        session.delete(k)
    replies: dict[str, int] = {}
    for k in plan["query"]:
        for reply in session.get(k, payload=MARK + b" query", timeout=0.5,
                                 allowed_destination=remote):
            if reply.ok is not None:
                replies[str(reply.ok.key_expr)] = replies.get(str(reply.ok.key_expr), 0) + 1
    keep.append(session.liveliness().declare_token(plan["control_token"]))
    for _ in range(CONTROL_ROUNDS):
        for k in plan["control_put"]:
            session.put(k, MARK + b" control")
    with lock:
        report = {"heard": dict(heard), "tokens_seen": seen,
                  "replies": replies, "asked": list(asked)}
    print(json.dumps(report), flush=True)
    print("done", flush=True)
    sys.stdin.readline()  # bye
    with lock:
        print(json.dumps({"asked": list(asked)}), flush=True)
    session.close()
    return 0


if __name__ == "__main__":
    sys.exit(main())
