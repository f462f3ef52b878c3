#!/usr/bin/python3
"""Reads Prometheus text exposition on stdin with prometheus_client's own parser (the oracle:
nobody here wrote it) and prints its samples as JSON lines: {"name", "labels", "value", "type"}.
Exits 1 with the parser's message when the text does not parse."""
import json
import sys

from prometheus_client.parser import text_string_to_metric_families


def main():
    text = sys.stdin.read()
    try:
        for family in text_string_to_metric_families(text):
            for s in family.samples:
                print(json.dumps({"family": family.name, "type": family.type, "name": s.name,
                                  "labels": s.labels, "value": s.value}, sort_keys=True))
    except Exception as e:  # the parser raises ValueError and others on malformed text
        print(f"prometheus_client cannot parse the exposition: {e}", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
