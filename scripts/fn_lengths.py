#!/usr/bin/env python3
"""Lists Rust functions longer than a limit (raw lines, signature to closing brace), tests left out.

    scripts/fn_lengths.py [--max 120] [--top N] [PATH ...]      (default PATH: src)

Exit status 1 when a function outside `#[cfg(test)]` modules and `tests/` is longer than --max: the
test command runs it so that no body grows past the limit again. Comments, strings and char literals
are skipped when braces are matched.
"""
import argparse
import pathlib
import re
import sys

FN = re.compile(r"^\s*(pub(\([^)]*\))?\s+)?(const\s+)?(async\s+)?(unsafe\s+)?(extern\s+\"[^\"]*\"\s+)?fn\s+(\w+)")


def code_only(text):
    """The text with comments and string/char literal contents blanked (newlines kept)."""
    out, i, n = [], 0, len(text)
    while i < n:
        c = text[i]
        if text.startswith("//", i):
            j = text.find("\n", i)
            j = n if j < 0 else j
            out.append(" " * (j - i))
            i = j
        elif text.startswith("/*", i):
            depth, j = 1, i + 2
            while j < n and depth:
                if text.startswith("/*", j):
                    depth, j = depth + 1, j + 2
                elif text.startswith("*/", j):
                    depth, j = depth - 1, j + 2
                else:
                    j += 1
            out.append("".join(ch if ch == "\n" else " " for ch in text[i:j]))
            i = j
        elif c == "r" and re.match(r'r#*"', text[i:i + 260]) and (i == 0 or not text[i - 1].isalnum()):
            hashes = re.match(r'r(#*)"', text[i:]).group(1)
            end = text.find('"' + hashes, i + len(hashes) + 2)
            j = n if end < 0 else end + 1 + len(hashes)
            out.append("".join(ch if ch == "\n" else " " for ch in text[i:j]))
            i = j
        elif c == '"':
            j = i + 1
            while j < n and text[j] != '"':
                j += 2 if text[j] == "\\" else 1
            out.append("".join(ch if ch == "\n" else " " for ch in text[i:j + 1]))
            i = j + 1
        elif c == "'" and re.match(r"'(\\.|[^\\'])'|'\\u\{[0-9a-fA-F]+\}'|'\\x[0-9a-fA-F]{2}'", text[i:i + 12]):
            m = re.match(r"'(\\.|[^\\'])'|'\\u\{[0-9a-fA-F]+\}'|'\\x[0-9a-fA-F]{2}'", text[i:i + 12])
            out.append(" " * len(m.group(0)))
            i += len(m.group(0))
        else:
            out.append(c)
            i += 1
    return "".join(out)


def functions(path):
    """(name, first line, line count, inside a test module) of every fn with a body."""
    code = code_only(path.read_text()).split("\n")
    test_depth = None  # brace depth at which a #[cfg(test)] module opened
    depth, pending_test, found, stack = 0, False, [], []
    nesting = 0  # ( and [ depth: a ';' inside them (an array type) ends nothing
    for number, line in enumerate(code, 1):
        if "#[cfg(test)]" in line:
            pending_test = True
        m = FN.match(line)
        if m:
            stack.append([m.group(7), number, depth, test_depth is not None])
        for ch in line:
            if ch in "([":
                nesting += 1
            elif ch in ")]":
                nesting -= 1
            elif ch == "{":
                if pending_test and test_depth is None:
                    test_depth = depth
                pending_test = False
                depth += 1
            elif ch == "}":
                depth -= 1
                if test_depth is not None and depth == test_depth:
                    test_depth = None
                if stack and depth == stack[-1][2]:
                    name, start, _, in_test = stack.pop()
                    found.append((name, start, number - start + 1, in_test))
            elif ch == ";" and nesting == 0 and stack and depth == stack[-1][2]:
                stack.pop()  # a declaration without a body (trait method, extern fn)
    return found


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("paths", nargs="*", default=["src"])
    parser.add_argument("--max", type=int, default=120)
    parser.add_argument("--top", type=int, default=0, help="also list the N longest functions")
    args = parser.parse_args()
    rows = []
    for root in args.paths:
        for path in sorted(pathlib.Path(root).rglob("*.rs")):
            rows += [(n, name, path, start) for name, start, n, in_test in functions(path) if not in_test]
    rows.sort(reverse=True)
    for n, name, path, start in rows[: args.top]:
        print(f"{n:5} {path}:{start} {name}")
    over = [r for r in rows if r[0] > args.max]
    for n, name, path, start in over:
        print(f"{path}:{start}: fn {name} is {n} lines (limit {args.max})", file=sys.stderr)
    print(f"{len(rows)} functions, {len(over)} over {args.max} lines", file=sys.stderr)
    return 1 if over else 0


if __name__ == "__main__":
    sys.exit(main())
