"""The report says what the force model assumes about the magnet's pocket next to the drawing that shows the pocket:
the stack-up figure's caption carries MODEL_DESCRIPTION, HTML-escaped as the template does."""

from __future__ import annotations

import re

from markupsafe import escape

import magfab.models.mechanics as mech


def test_stackup_caption_says_what_the_fe_models(default_build):
    html = (default_build.out_dir / "report.html").read_text(encoding="utf-8")
    figure = re.search(r'<figure id="stackup">(.*?)</figure>', html, re.S)
    assert figure, "no stack-up figure in the report"
    caption = re.search(r"<figcaption>(.*?)</figcaption>", figure.group(1), re.S).group(1)
    note = re.search(r'<span id="stackup-model">(.*?)</span>', caption, re.S)
    assert note, "the stack-up caption has no note on the force model"
    text = " ".join(note.group(1).split())
    assert "<code>fe</code>" in text  # the build's model (auto picks the FE for MagOne)
    y = default_build.design.material.yeoh  # the default law for Ecoflex 00-30 (predict.material_law = "auto")
    law = f"Yeoh (k2 = {y.k2:.3g}, k3 = {y.k3:.3g}, recipes/materials.toml)"
    assert " ".join(str(escape(mech.MODEL_DESCRIPTION.replace("neo-Hookean", law))).split()) in text
    assert "'" not in text and "&#39;" in text  # escaped, not raw (the description has an apostrophe)
