"""Runs `gonio ARGS` (argv[2:]) and acts at exact points of it, for the tests of how a scan ends
(test_gonio_endings.py): argv[1] is a JSON file of steps, taken in turn. A step acts just before
the `nth` audit event `at` with an argument that the regex `match` finds, or with `at` "call"
as a function `match` finds ("file.py:name") is called: `do` is a signal's name (the scan
sends it to itself there) or "immutable" (`chattr +i` on each path the glob `paths` finds).
Each step taken is appended to the steps file's name + ".taken", one index a line."""

import glob
import json
import os
import re
import runpy
import signal
import subprocess
import sys
from pathlib import Path

steps_file = Path(sys.argv[1])
steps = json.loads(steps_file.read_text())
taken = steps_file.with_name(steps_file.name + ".taken")
seen, done = [0], [0]


def act() -> None:
    step = steps.pop(0)
    with taken.open("a") as fh:
        fh.write(f"{done[0]}\n")
    seen[0], done[0] = 0, done[0] + 1
    if step["do"] == "immutable":
        for path in glob.glob(step["paths"]):
            subprocess.run(["chattr", "+i", path], check=True)
    else:
        os.kill(os.getpid(), getattr(signal, step["do"]))


def matching(at: str, subjects: tuple) -> bool:
    """Whether this is the head step's nth match."""
    step = steps[0]
    if step["at"] != at or not any(re.search(step["match"], str(s)) for s in subjects):
        return False
    seen[0] += 1
    return seen[0] == step.get("nth", 1)


def on_audit(event: str, args: tuple) -> None:
    if steps and matching(event, args):
        act()


def on_call(frame, event: str, arg: object) -> None:
    code = frame.f_code
    if event == "call" and steps and matching("call", (f"{code.co_filename}:{code.co_name}",)):
        act()


sys.addaudithook(on_audit)
if any(step["at"] == "call" for step in steps):
    sys.setprofile(on_call)
sys.argv = ["gonio", *sys.argv[2:]]
runpy.run_module("gonio_cli", run_name="__main__", alter_sys=True)
