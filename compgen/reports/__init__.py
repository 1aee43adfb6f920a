"""The library's reports: the comparison with post data, the one-screen verdict, the
checklist, the plots and the HTML report. The commands print them; nothing here parses a
command line."""
