#!/usr/bin/env python3
"""List the C++ functions of a tree longer than a limit (lines from the signature to the closing brace).

    scripts/function_lengths.py runtime/src [--limit 150]

A function is a brace block that opens at namespace or class scope after a parenthesised
signature; lambdas and local classes count as part of the function that holds them. Comments,
strings and character literals are skipped. Exits 1 when a function exceeds the limit.
"""
import argparse
import pathlib
import re
import sys


def strip(text):
    """The text with comments and string/char literals blanked (newlines kept)."""
    out, i, n = [], 0, len(text)
    while i < n:
        c = text[i]
        if text.startswith("//", i):
            j = text.find("\n", i)
            j = n if j < 0 else j
            out.append(" " * (j - i)); i = j
        elif text.startswith("/*", i):
            j = text.find("*/", i + 2)
            j = n if j < 0 else j + 2
            out.append(re.sub(r"[^\n]", " ", text[i:j])); i = j
        elif text.startswith('R"', i):
            m = re.match(r'R"([^(\s]*)\(', text[i:])
            end = text.find(")" + m.group(1) + '"', i) if m else -1
            j = n if end < 0 else end + len(m.group(1)) + 2
            out.append(re.sub(r"[^\n]", " ", text[i:j])); i = j
        elif c in "\"'":
            j = i + 1
            while j < n and text[j] != c:
                j += 2 if text[j] == "\\" else 1
            out.append(" " * (j + 1 - i)); i = j + 1
        else:
            out.append(c); i += 1
    return "".join(out)


def functions(path):
    text = strip(path.read_text(errors="replace"))
    scopes = []  # (kind, start line, name)
    line = 1
    for i, c in enumerate(text):
        if c == "\n":
            line += 1
        elif c == "{":
            head = text[max(0, i - 400):i]
            head = head[head.rfind(";") + 1:] if ";" in head else head
            head = head[head.rfind("}") + 1:] if "}" in head else head
            inside_function = any(k == "function" for k, _, _ in scopes)
            is_function = (not inside_function and re.search(r"\)\s*(const|noexcept|override|final|->[^{]*|:[^{]*)*\s*$", head)
                           and not re.search(r"\b(namespace|class|struct|enum|union)\b[^()]*$", head)
                           and not re.search(r"\b(if|for|while|switch|catch)\s*\(", head.split("\n")[-1]))
            name = re.findall(r"([\w:~]+)\s*\(", head)
            scopes.append(("function" if is_function else "block", line, name[0] if name else "?"))
        elif c == "}" and scopes:
            kind, start, name = scopes.pop()
            if kind == "function":
                yield name, start, line


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("root")
    parser.add_argument("--limit", type=int, default=150)
    args = parser.parse_args()
    long = []
    for path in sorted(pathlib.Path(args.root).rglob("*")):
        if path.suffix not in (".cpp", ".hpp", ".h", ".cc"):
            continue
        for name, start, end in functions(path):
            if end - start + 1 > args.limit:
                long.append((end - start + 1, f"{path}:{start}", name))
    for length, where, name in sorted(long, reverse=True):
        print(f"{length:5d} lines  {where}  {name}")
    if long:
        print(f"{len(long)} function(s) over {args.limit} lines")
        return 1
    print(f"no function over {args.limit} lines")
    return 0


if __name__ == "__main__":
    sys.exit(main())
