"""A tool that never finishes: records itself, starts a grandchild in its process group, and
sleeps (for the tests that kill adaptune and look for orphans).

usage: stubborn.py WORKDIR RECORD_DIR -> RECORD_DIR/<pid>.json {"pid", "child", "workdir"}
"""

import json
import os
import subprocess
import sys
import time

workdir, record_dir = sys.argv[1], sys.argv[2]
child = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(600)"])
tmp = os.path.join(record_dir, f".{os.getpid()}.tmp")
with open(tmp, "w") as fh:
    json.dump({"pid": os.getpid(), "child": child.pid, "workdir": workdir}, fh)
os.replace(tmp, os.path.join(record_dir, f"{os.getpid()}.json"))
time.sleep(600)
