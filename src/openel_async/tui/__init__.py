"""The terminal UI of ``openel-async jog`` (built on Textual): every component of a rig with
its state and live values, plots of the selected ones, keyboard jogging of the selected axis
within its limits, enable/disable, the rig's e-stop on one key, and the event and error log.

- :mod:`.jogger`: what the UI does to the rig (no Textual): :class:`~.jogger.Jogger`;
- :mod:`.app`: the Textual app, :class:`~.app.JogApp`; :mod:`.widgets`: its panels.

Importing this package imports neither Textual nor the rig: each module loads what it uses.
"""
