#!/usr/bin/env python3
"""Lists the functions longer than a limit (default 80 lines) in the tracked C++ sources outside
test/, longest first; exits 1 when there is one.

  scripts/long_functions.py [LIMIT]

A brace-matching scan, not a parser: comments, strings and preprocessor lines are blanked, then a
'{' opens a function body when the text since the last ';', '{' or '}' ends in a parameter list
(with qualifiers, a trailing return type or a constructor's initializers) that does not belong to
a control statement, a lambda or a class or namespace head. Lambdas count toward the function that
holds them. A function's length runs from the first line of its head to its closing brace.
"""
import re
import subprocess
import sys

NOT_FUNCTIONS = {"if", "for", "while", "switch", "catch", "return", "sizeof", "decltype", "alignas",
                 "alignof", "static_assert", "defined", "noexcept"}


def blank(src):
    """src with comments, string and character literals and preprocessor lines replaced by spaces
    (newlines kept, so line numbers hold)."""
    out, i, n = [], 0, len(src)
    while i < n:
        c = src[i]
        if src.startswith("//", i):
            j = src.find("\n", i)
            j = n if j < 0 else j
            out.append(" " * (j - i))
            i = j
        elif src.startswith("/*", i):
            j = src.find("*/", i + 2)
            j = n if j < 0 else j + 2
            out.append(re.sub(r"[^\n]", " ", src[i:j]))
            i = j
        elif src.startswith('R"', i) and (i == 0 or not (src[i - 1].isalnum() or src[i - 1] == "_")):
            delim = re.match(r'R"([^(\s]*)\(', src[i:]).group(1)
            j = src.find(")" + delim + '"', i) + len(delim) + 2
            out.append('""' + re.sub(r"[^\n]", " ", src[i + 2:j]))
            i = j
        elif c == '"' or (c == "'" and not (i > 0 and src[i - 1].isalnum())):  # not a digit separator
            j = i + 1
            while j < n and src[j] != c:
                j += 2 if src[j] == "\\" else 1
            out.append(c + " " * (j - i - 1) + c)
            i = j + 1
        elif c == "#" and src[src.rfind("\n", 0, i) + 1:i].strip() == "":
            j = i
            while True:  # a directive continues past escaped newlines
                k = src.find("\n", j)
                k = n if k < 0 else k
                if src[k - 1:k] != "\\":
                    break
                j = k + 1
            out.append(re.sub(r"[^\n]", " ", src[i:k]))
            i = k
        else:
            out.append(c)
            i += 1
    return "".join(out)


def function_name(head):
    """The name of the function whose head (the text before its '{') is `head`, or None."""
    h = head.strip()
    init_list = re.search(r"\)\s*(noexcept\s*)?:\s*[\w:]+\s*[\(\{]", h)
    params_end = re.search(r"\)\s*(const|noexcept|override|final|mutable|&|&&|\s|->\s*[\w:<>,\s\*&]+)*\s*$", h)
    if init_list:
        close = init_list.start()
    elif params_end:
        close = params_end.start()
    else:
        return None
    depth = 0
    for k in range(close, -1, -1):  # back to the '(' that opens the parameter list
        if h[k] == ")":
            depth += 1
        elif h[k] == "(":
            depth -= 1
            if depth == 0:
                break
    else:
        return None
    before = h[:k].rstrip()
    if before.endswith("]"):  # a lambda
        return None
    m = re.search(r"((?:[\w~]+\s*(?:<[^;{}]*?>)?\s*::\s*)*(?:operator\s*[^\s(]+|~?\w+))\s*$", before)
    if not m:
        return None
    last = m.group(1).split("::")[-1].strip()
    if last in NOT_FUNCTIONS or last.startswith("ACT_"):
        return None
    rest = before[:m.start()].strip()
    if rest.endswith("=") or rest.endswith("return"):
        return None
    return re.sub(r"\s+", "", m.group(1))


def functions(path):
    """(name, first line, last line) of every function defined in `path`."""
    text = blank(open(path, encoding="utf-8", errors="replace").read())
    found, stack, last = [], [], 0  # stack: (is_function, name, first line)
    line_of = lambda pos: text.count("\n", 0, pos) + 1
    for i, c in enumerate(text):
        if c == "{":
            name = None if any(f for f, _, _ in stack) else function_name(text[last:i])
            head = text[last:i]
            start = line_of(last + len(head) - len(head.lstrip()))
            stack.append((name is not None, name, start))
            last = i + 1
        elif c == "}":
            if stack:
                is_function, name, start = stack.pop()
                if is_function:
                    found.append((name, start, line_of(i)))
            last = i + 1
        elif c == ";":
            last = i + 1
    return found


def main():
    limit = int(sys.argv[1]) if len(sys.argv) > 1 else 80
    files = subprocess.run(["git", "ls-files", "*.cc", "*.h", "*.inc", "*.cpp", "*.hpp", "*.ino"],
                           capture_output=True, text=True, check=True).stdout.split()
    rows = []
    for f in files:
        if f.startswith("test/"):
            continue
        for name, first, end in functions(f):
            if end - first + 1 > limit:
                rows.append((end - first + 1, f, first, name))
    for n, f, first, name in sorted(rows, reverse=True):
        print(f"{n:5d}  {f}:{first}  {name}")
    print(f"{len(rows)} functions over {limit} lines outside test/", file=sys.stderr)
    return 1 if rows else 0


if __name__ == "__main__":
    sys.exit(main())
