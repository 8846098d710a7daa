"""Start FreeTAKServer 2.2.1 on loopback only, its files in one folder: run by the Python of FreeTAKServer's own
virtualenv (tests/test_tak_server.py), with FreeTAKServer's own arguments after the folder:

    python fts_launch.py FOLDER -CoTIP 127.0.0.1 -CoTPort PORT ...

The environment (FTS_* variables, set by the test) moves its configuration, databases, certificates and ports.
Three things it cannot move are patched here, before its modules load, and nothing else:
- its configuration module creates /opt/fts at import (FreeTAKServer's fixed persistence path): skipped;
- three components keep their databases under that fixed path (read from the module's PERSISTENCE_PATH): FOLDER;
- its data package web services listen on 0.0.0.0 whatever address they are given (their constants class
  hard-codes it): 127.0.0.1.
"""

from __future__ import annotations

import os
import runpy
import sys

FIXED_PATH = "/opt/fts"


def main() -> None:
    folder, fts_args = sys.argv[1], sys.argv[2:]
    real_mkdir = os.mkdir
    os.mkdir = lambda p, *a, **k: None if str(p).rstrip("/") == FIXED_PATH else real_mkdir(p, *a, **k)
    try:
        from FreeTAKServer.core.configuration import MainConfig
    finally:
        os.mkdir = real_mkdir
    MainConfig.PERSISTENCE_PATH = folder

    from FreeTAKServer.core.configuration import DataPackageServerConstants as constants

    init = constants.DataPackageServerConstants.__init__

    def loopback_init(self, *args, **kwargs):
        init(self, *args, **kwargs)
        self.IP = "127.0.0.1"

    constants.DataPackageServerConstants.__init__ = loopback_init
    sys.argv = ["FreeTAKServer", *fts_args]
    runpy.run_module("FreeTAKServer.controllers.services.FTS", run_name="__main__", alter_sys=True)


if __name__ == "__main__":
    main()
