"""One photo's verification as values and as files: report.json, report.html.

`report` runs the verification of a scene against its fit (`verify_scene`) and writes its
folder; `findings` holds its values (`Report`) and report.json's fields; `html_report`
renders report.html and bench.html from `templates/`; `crosscheck` sets our fit beside a
NeRF-path run of the same scene.

May import: verify.metrics, verify.verdict, inverse, scenes.
"""
