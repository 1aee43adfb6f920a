"""The command line (click: parse, call, print) and what only commands assemble: the
comparison with post data, the HTML report, its plots, the checklist."""
