"""Sphinx extension: each inline or linked script once per page.

sphinx-thebe (pulled in by Jupyter Book 1) registers its inline ``const THEBE_JS_URL = …``
configuration on every ``env-before-read-docs`` event; when that fires twice in one build the
page declares the constant twice and the browser logs "Uncaught SyntaxError: Identifier
'THEBE_JS_URL' has already been declared".  This drops repeated script entries from the page
context before the page is written.
"""


def _unique_scripts(app, pagename, templatename, context, doctree):  # noqa: ARG001
    scripts = context.get("script_files")
    if not scripts:
        return
    seen, unique = set(), []
    for script in scripts:
        key = (script.filename or "", tuple(sorted((k, str(v)) for k, v in
                                                  script.attributes.items())))
        if key not in seen:
            seen.add(key)
            unique.append(script)
    scripts[:] = unique


def setup(app):
    app.connect("html-page-context", _unique_scripts, priority=900)
    return {"parallel_read_safe": True, "parallel_write_safe": True}
