"""The command line (click: parse, call, print): a thin layer over the library's API."""
