"""Jinja2 templates (firmware, readout package, checklist, report), shipped inside the wheel as
``magfab.templates``; read them with :func:`importlib.resources.files`."""
