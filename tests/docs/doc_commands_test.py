#!/usr/bin/env python3
"""Every command the README and docs/ show in a bash block must exist as shown.

For each command line (continuations joined): a headcast program must exist,
each subcommand it names must be one of the program's, and each --flag must be
listed in the --help of that (sub)command or of the program (hidden aliases
of old names do not count: documentation shows the current names). Scripts
must exist and parse (bash -n). The cheap commands run for real (--version,
--help, headcast-avatar info, headcast-headmodel summary, headcast-rec info on
shipped files) and must succeed. Links to the repository's files must resolve
in a clone.

usage: doc_commands_test.py ROOT BIN_DIR
"""
import os
import re
import shlex
import subprocess
import sys

root, bin_dir = os.path.abspath(sys.argv[1]), os.path.abspath(sys.argv[2])
failures, checked, ran = [], 0, 0
help_cache = {}


def helptext(argv):
    key = tuple(argv)
    if key not in help_cache:
        p = subprocess.run(argv + ["--help"], capture_output=True, text=True, timeout=60)
        help_cache[key] = p.stdout + p.stderr
    return help_cache[key]


def subcommands(text):
    names, inside = [], False
    for line in text.splitlines():
        if line.strip().lower().startswith("subcommands:"):
            inside = True
            continue
        if inside:
            m = re.match(r"^  (\S+)", line)
            if m:
                names.append(m.group(1))
            elif line.strip() and not line.startswith("  "):
                inside = False
    return names


def flags_in(text):
    return set(re.findall(r"(?<![\w-])(--[A-Za-z0-9][A-Za-z0-9-]*)", text))


def commands(path):
    text = open(path).read()
    for block in re.findall(r"```(?:bash|sh)\n(.*?)```", text, re.S):
        joined = re.sub(r"\\\n\s*", " ", block)
        for line in joined.splitlines():
            line = line.strip()
            if line and not line.startswith("#"):
                yield line


def split_pipeline(tokens):
    part = []
    for t in tokens:
        if t in ("|", "&&", "||", ";", "&"):
            if part:
                yield part
            part = []
        else:
            part.append(t)
    if part:
        yield part


def check(doc, line, argv):
    global checked, ran
    while argv and (re.match(r"^[A-Z_]+=", argv[0]) or argv[0] in ("sudo", "time", "exec")):
        argv = argv[1:]
    if argv[:1] == ["taskset"]:
        argv = argv[3:]
    if argv[:1] == ["(umask"] or not argv:
        return
    prog = argv[0]
    name = os.path.basename(prog)
    where = f"{doc}: {line}"
    if name.startswith("headcast-"):
        exe = os.path.join(bin_dir, name)
        if not os.path.exists(exe):
            failures.append(f"{where}\n    no program {name}")
            return
        checked += 1
        chain = [exe]
        text = helptext(chain)
        top = flags_in(text)
        args = [a.strip("[]") for a in argv[1:]]
        subs = subcommands(text)
        i = 0
        while i < len(args) and subs:
            a = args[i]
            if a.startswith("-"):
                break
            if a in subs:
                chain.append(a)
                text = helptext(chain)
                subs = subcommands(text)
                i += 1
                continue
            failures.append(f"{where}\n    {a}: not a subcommand of {' '.join(os.path.basename(c) for c in chain)}")
            return
        known = flags_in(text) | top
        for a in args[i:]:
            if a.startswith("--"):
                flag = a.split("=", 1)[0]
                if flag not in known:
                    failures.append(f"{where}\n    {flag}: not in the --help of {' '.join(os.path.basename(c) for c in chain)}")
        # The cheap ones run for real.
        cheap = ("--version" in args or "--help" in args or
                 (len(chain) > 1 and os.path.basename(chain[-1]) in ("info", "summary") and
                  all(os.path.exists(os.path.join(root, a)) for a in args[i:] if not a.startswith("-") and "." in a)))
        if cheap and "..." not in line and "<" not in line:
            p = subprocess.run([chain[0]] + argv[1:], cwd=root, capture_output=True, text=True, timeout=120)
            ran += 1
            if p.returncode != 0:
                failures.append(f"{where}\n    ran and failed ({p.returncode}): {p.stderr.strip()[-300:]}")
    elif prog.startswith(("deploy/", "bench/", "tests/")):
        path = os.path.join(root, prog)
        checked += 1
        if not os.path.exists(path):
            failures.append(f"{where}\n    no script {prog}")
        elif path.endswith(".sh") and subprocess.run(["bash", "-n", path]).returncode != 0:
            failures.append(f"{where}\n    {prog} does not parse")
    elif prog in ("python3", "/usr/bin/python3") and len(argv) > 1 and argv[1].endswith(".py"):
        checked += 1
        if not os.path.exists(os.path.join(root, argv[1])):
            failures.append(f"{where}\n    no script {argv[1]}")


docs = [os.path.join(root, "README.md")] + sorted(
    os.path.join(root, "docs", f) for f in os.listdir(os.path.join(root, "docs")) if f.endswith(".md"))
for doc in docs:
    rel = os.path.relpath(doc, root)
    for line in commands(doc):
        try:
            tokens = shlex.split(line, comments=True)
        except ValueError as e:
            failures.append(f"{rel}: {line}\n    cannot be split: {e}")
            continue
        for argv in split_pipeline(tokens):
            check(rel, line, argv)

# Links to files of the repository must resolve in a clone (no ../shared, no build outputs).
links = 0
for doc in docs:
    rel = os.path.relpath(doc, root)
    for target in re.findall(r"\]\(([^)#\s]+)(?:#[^)]*)?\)", open(doc).read()):
        if re.match(r"^[a-z]+:", target):
            continue
        links += 1
        path = os.path.normpath(os.path.join(os.path.dirname(doc), target))
        if not os.path.exists(path) or not os.path.abspath(path).startswith(os.path.abspath(root)):
            failures.append(f"{rel}: link {target} does not resolve inside the repository")

print(f"doc commands: {checked} checked, {links} links, {ran} run, {len(failures)} failing")
for f in failures:
    print("FAIL " + f)
if checked < 20:
    print("FAIL fewer than 20 commands found: is the parser still reading the docs?")
    sys.exit(1)
sys.exit(1 if failures else 0)
