#!/usr/bin/env python3
"""No coefficient's name in the web's code (issue 37): the coefficients' keys, groups, titles,
units, stage 3's states and the seed's targets are imucald's (GET /api/schema, made from
core/coefficients.cpp and plan/), and the browser reads them from there (web/js/schema.mjs). A
string literal in web/js/**/*.mjs (or .js) holding a coefficient's name ('gyro.bias_dph',
"accel.lever_arm_mm.y.", `gyro.noise.arw_deg_rth` ...: "gyro" or "accel", a dot and a name) is a
copy of the C++ tables, which drifts from them when a coefficient is added or renamed: it fails
the suite with the file and line. Comments may name coefficients (examples of what a function
takes); tests/ may too.

A name built from parts (`${triad}.noise`) is not a copy and is not looked for; neither are the
prefixes 'gyro.' and 'accel.' alone (which triad a name is).

Usage: check_web_coefficient_names.py SOURCE_ROOT
"""
import os
import re
import sys

WEB_DIR = os.path.join("web", "js")
# A name of the model: the triad, a dot, and the start of a key (a letter or an underscore).
NAME = re.compile(r"\b(?:gyro|accel)\.[A-Za-z_]\w*")
# After one of these (or at the start) a slash opens a regular expression, not a division.
REGEX_BEFORE = set("(,=:[!&|?{};+-*%<>~^")
REGEX_AFTER_WORDS = {"return", "typeof", "case", "do", "else", "in", "of", "new", "delete", "void", "throw"}


def skip_regex(text, i):
    """The index after the regular expression literal that starts at text[i] == '/'."""
    j, n, in_class = i + 1, len(text), False
    while j < n and text[j] != "\n":
        c = text[j]
        if c == "\\":
            j += 2
            continue
        if c == "[":
            in_class = True
        elif c == "]":
            in_class = False
        elif c == "/" and not in_class:
            j += 1
            while j < n and text[j].isalpha():  # flags
                j += 1
            return j
        j += 1
    return j


def skip_string(text, i):
    """The index after the string literal opened by text[i] (' " or `)."""
    quote, j, n = text[i], i + 1, len(text)
    while j < n and text[j] != quote:
        j += 2 if text[j] == "\\" else 1
    return min(j + 1, n)


def regex_may_start(text, i):
    """Whether a slash at text[i] opens a regular expression (by what precedes it)."""
    k = i - 1
    while k >= 0 and text[k] in " \t\r\n":
        k -= 1
    if k < 0 or text[k] in REGEX_BEFORE:
        return True
    m = re.search(r"(\w+)$", text[:k + 1])
    return bool(m) and m.group(1) in REGEX_AFTER_WORDS


def string_literals(text):
    """(line, text) of every string and template literal, comments and regular expressions
    skipped (a quote inside a regular expression opens no string)."""
    i, n = 0, len(text)
    while i < n:
        c, two = text[i], text[i:i + 2]
        if two == "//":
            j = text.find("\n", i)
            i = n if j < 0 else j
        elif two == "/*":
            j = text.find("*/", i + 2)
            i = n if j < 0 else j + 2
        elif c == "/" and regex_may_start(text, i):
            i = skip_regex(text, i)
        elif c in "\"'`":
            j = skip_string(text, i)
            yield text.count("\n", 0, i) + 1, text[i:j]
            i = j
        else:
            i += 1


def sources(root):
    for dirpath, _, files in os.walk(os.path.join(root, WEB_DIR)):
        for f in sorted(files):
            if f.endswith((".mjs", ".js")):
                yield os.path.relpath(os.path.join(dirpath, f), root)


def main():
    root = sys.argv[1]
    problems = []
    for rel in sorted(sources(root)):
        text = open(os.path.join(root, rel), encoding="utf-8").read()
        for line, literal in string_literals(text):
            for name in NAME.findall(literal):
                problems.append(f"{rel}:{line}: the coefficient name '{name}' in {literal[:70]}")
    if problems:
        print("A coefficient's name as a string in the web's code: a copy of imucald's tables, which")
        print("drifts from them. Read it from GET /api/schema instead (web/js/schema.mjs):")
        print("\n".join(problems))
        return 1
    print("No coefficient's name as a string in web/js: every one comes from GET /api/schema")
    return 0


if __name__ == "__main__":
    sys.exit(main())
