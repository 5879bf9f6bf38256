#!/usr/bin/env python3
"""Function sizes (issue 37): no C++ function of daemon/, estimators/ or pipeline/ longer than 80
lines, no function of a web module longer than 150, unless it is a table of data and says so with
the marker `// function-size: a table of data` on the line above it.

The functions longer than that today are listed below with their length: the debt issue 37 pays
off. A listed function may shrink, never grow; one that no longer exceeds its limit must leave
the list (so the list only shrinks), and no other function may exceed the limit. Lengths count
the lines from the one holding the body's opening brace to the closing one, both included.

Usage: check_function_size.py SOURCE_ROOT [--list]   (--list prints every function over a limit)
"""
import os
import re
import sys

CPP_DIRS = ("daemon", "estimators", "pipeline")
CPP_LIMIT = 80
WEB_DIR = os.path.join("web", "js")
WEB_LIMIT = 150
MARKER = "function-size: a table of data"

# file: {function: lines}: the debt issue 37 found, paid off; a function over its limit now fails.
KNOWN = {}


def blank_comments_and_strings(text, js):
    """The text with comments, string and character literals replaced by spaces (newlines kept),
    so that braces and parentheses inside them do not count."""
    out = []
    i, n = 0, len(text)
    while i < n:
        c = text[i]
        two = text[i:i + 2]
        if two == "//":
            j = text.find("\n", i)
            j = n if j < 0 else j
            out.append(" " * (j - i))
            i = j
        elif two == "/*":
            j = text.find("*/", i + 2)
            j = n if j < 0 else j + 2
            out.append(re.sub(r"[^\n]", " ", text[i:j]))
            i = j
        elif not js and text.startswith('R"', i):
            m = re.match(r'R"([^(\s]*)\(', text[i:])
            if m:
                end = text.find(")" + m.group(1) + '"', i)
                j = n if end < 0 else end + len(m.group(1)) + 2
                out.append(re.sub(r"[^\n]", " ", text[i:j]))
                i = j
            else:
                out.append(c)
                i += 1
        elif c in "\"'" or (js and c == "`"):
            j = i + 1
            while j < n and text[j] != c:
                j += 2 if text[j] == "\\" else 1
            j = min(j + 1, n)
            out.append(re.sub(r"[^\n]", " ", text[i:j]))
            i = j
        else:
            out.append(c)
            i += 1
    return "".join(out)


CONTROL = {"if", "for", "while", "switch", "catch", "return", "sizeof", "decltype", "alignof", "static_assert",
           "requires", "noexcept", "throw", "new", "delete", "assert"}


def matching_open(text, close):
    depth = 0
    for k in range(close, -1, -1):
        if text[k] == ")":
            depth += 1
        elif text[k] == "(":
            depth -= 1
            if depth == 0:
                return k
    return -1


def matching_close(text, open_):
    depth = 0
    for k in range(open_, len(text)):
        if text[k] == "{":
            depth += 1
        elif text[k] == "}":
            depth -= 1
            if depth == 0:
                return k
    return len(text) - 1


def cpp_functions(text):
    """(name, line of the opening brace, lines) of each function definition not inside another."""
    found = []
    k = 0
    while True:
        k = text.find("{", k)
        if k < 0:
            return found
        before = text[:k].rstrip()
        # Qualifiers between the parameter list and the body.
        tail = re.search(r"\)\s*((const|noexcept|override|final|mutable|&|&&|->\s*[\w:<>,\s*&]+)\s*)*$", before)
        name = None
        if tail:
            close = before.rfind(")", 0, tail.start() + 1)
            open_ = matching_open(before, close)
            m = re.search(r"([\w:~]+|operator\S+)\s*$", before[:open_]) if open_ > 0 else None
            if m and m.group(1).split("::")[-1] not in CONTROL and not before[:open_].rstrip().endswith("]"):
                name = m.group(1)
                # A constructor's member initialisers (`: a_(x), b_(y) {`): walk back to its name.
                start = m.start(1)
                while True:
                    head = before[:start].rstrip()
                    if not (head.endswith(",") or (head.endswith(":") and not head.endswith("::"))):
                        break
                    head = head[:-1].rstrip()
                    if not head.endswith(")"):
                        break
                    o = matching_open(head, len(head) - 1)
                    m2 = re.search(r"([\w:~]+)\s*$", head[:o]) if o > 0 else None
                    if not m2:
                        break
                    name, start = m2.group(1), m2.start(1)
        end = matching_close(text, k)
        if name:
            first = text.count("\n", 0, k) + 1
            last = text.count("\n", 0, end) + 1
            found.append((name, first, last - first + 1))
            k = end + 1
        else:
            k += 1


JS_DECL = re.compile(r"(?:(?:async\s+)?function\s*\*?\s*(\w+)\s*\([^)]*\)\s*\{)"
                     r"|(?:(?:const|let)\s+(\w+)\s*=\s*(?:async\s*)?(?:\([^)]*\)|\w+)\s*=>\s*\{)")


def js_functions(text):
    found = []
    for m in JS_DECL.finditer(text):
        k = m.end() - 1
        end = matching_close(text, k)
        first = text.count("\n", 0, k) + 1
        last = text.count("\n", 0, end) + 1
        found.append((m.group(1) or m.group(2), first, last - first + 1))
    return found


def marked(lines, line):
    """Whether the function whose body opens on `line` (1-based) carries the marker above it."""
    for k in range(line - 2, max(line - 6, -1), -1):
        if MARKER in lines[k]:
            return True
    return False


def sources(root):
    for top, exts in [(d, (".cpp", ".hpp")) for d in CPP_DIRS] + [(WEB_DIR, (".mjs", ".js"))]:
        for dirpath, _, files in os.walk(os.path.join(root, top)):
            for f in sorted(files):
                if f.endswith(exts):
                    yield os.path.relpath(os.path.join(dirpath, f), root)


def main():
    root = sys.argv[1]
    listing = "--list" in sys.argv
    problems, over = [], {}
    for rel in sources(root):
        raw = open(os.path.join(root, rel), encoding="utf-8").read()
        js = rel.endswith((".mjs", ".js"))
        limit = WEB_LIMIT if js else CPP_LIMIT
        text = blank_comments_and_strings(raw, js)
        lines = raw.split("\n")
        for name, line, length in (js_functions(text) if js else cpp_functions(text)):
            if length > limit and not marked(lines, line):
                over.setdefault(rel, {})[name] = max(length, over.get(rel, {}).get(name, 0))
    for rel, functions in sorted(over.items()):
        for name, length in sorted(functions.items()):
            known = KNOWN.get(rel, {}).get(name)
            limit = WEB_LIMIT if rel.startswith(WEB_DIR) else CPP_LIMIT
            if listing:
                print(f"{length:5d}  {rel}: {name}")
            if known is None:
                problems.append(f"{rel}: {name} is {length} lines, over the {limit} a function may have (split it; a "
                                f"table of data says so with `// {MARKER}` above it)")
            elif length > known:
                problems.append(f"{rel}: {name} grew to {length} lines from {known}: it is over the limit of {limit} "
                                "already; split it instead")
    for rel, functions in sorted(KNOWN.items()):
        for name, known in sorted(functions.items()):
            if name not in over.get(rel, {}):
                problems.append(f"{rel}: {name} is no longer over its limit (or is gone): remove it from KNOWN in "
                                "tests/architecture/check_function_size.py")
    for p in problems:
        print(p)
    total = sum(len(f) for f in KNOWN.values())
    if problems:
        print(f"function sizes: {len(problems)} problem(s)")
        return 1
    print(f"function sizes: no function over its limit but the {total} listed (issue 37's debt)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
