"""Acquisition hardware for the light stage: a turntable, LED boards and a camera on a serial line.

Modules, one concept each:

- :mod:`rig.wire`: the line format of docs/rig-protocol.md (checksums, commands, replies);
- :mod:`rig.transport`: lines over pyserial (``serial_for_url``: real ports, ``socket://``, ``loop://``);
- :mod:`rig.client`: numbered commands with timeouts, retries and restart detection;
- :mod:`rig.errors`: the failures, each naming the port and the last command;
- :mod:`rig.camera`: trigger an exposure, wait for the image file in a folder;
- :mod:`rig.plan`: capture plans (JSON) and their expansion into Algorithm 1;
- :mod:`rig.session`: the session folder, its journal and ``manifest.json``;
- :mod:`rig.runner`: run a plan, resumably;
- :mod:`rig.sim`: a simulated rig speaking the same protocol, with fault injection.

``rig`` sits outside ``abs/`` and above every abs layer but the command line: it imports
``abs.errors``, ``abs.camera``, ``abs.io`` (and ``abs.render``, ``abs.studies`` for abs-rendered
simulated frames); ``abs rig`` (``abs/cli/rig.py``) imports it lazily.
"""
