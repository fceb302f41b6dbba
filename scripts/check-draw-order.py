#!/usr/bin/env python3
"""Fails when a call's arguments draw from a random engine more than once: C++ leaves the order of argument
evaluation to the compiler, so GCC and clang builds would draw different noise (`Vector3d(g(rng), g(rng), g(rng))`).
Braces (`Vector3d{...}`) or one draw per declaration fix the order. Usage: check-draw-order.py FILE..."""
import re
import sys

KEYWORDS = {"for", "while", "if", "switch", "return", "sizeof", "catch"}
ENGINE = re.compile(r"std::(?:mt19937(?:_64)?|default_random_engine|minstd_rand0?|ranlux\w*|knuth_b)\s+(\w+)")


def top_level_args(text):
    depth, parts, cur = 0, [], []
    for ch in text:
        if ch in "([{":
            depth += 1
        elif ch in ")]}":
            depth -= 1
        if ch == "," and depth == 0:
            parts.append("".join(cur))
            cur = []
        else:
            cur.append(ch)
    parts.append("".join(cur))
    return parts


def closing(text, i):
    depth = 0
    for j in range(i, len(text)):
        if text[j] == "(":
            depth += 1
        elif text[j] == ")":
            depth -= 1
            if depth == 0:
                return j
    return -1


def findings(path):
    text = open(path, encoding="utf-8", errors="replace").read()
    engines = set(ENGINE.findall(text)) | {"rng"}
    draw = re.compile(r"\w\s*\(\s*(?:\w+(?:\.|->))?(?:%s)\s*\)" % "|".join(map(re.escape, sorted(engines))))
    for m in re.finditer(r"(\w+)\s*\(", text):
        if m.group(1) in KEYWORDS:
            continue
        open_at = m.end() - 1
        close_at = closing(text, open_at)
        if close_at < 0:
            continue
        args = top_level_args(text[open_at + 1 : close_at])
        if sum(1 for a in args if draw.search(a)) >= 2:
            yield text.count("\n", 0, open_at) + 1, text[m.start() : close_at + 1][:100]


def main():
    bad = [(p, line, call) for p in sys.argv[1:] for line, call in findings(p)]
    for p, line, call in bad:
        print(f"{p}:{line}: two random draws in one call's arguments (order left to the compiler): {call}", file=sys.stderr)
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
