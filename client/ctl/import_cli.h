/* import_cli — the `clipmapctl import` subcommand: argument handling and the report line; the
 * work is import.c. Only clipmapctl's main calls it (it prints to stdout/stderr). */
#ifndef CLIPMAP_IMPORT_CLI_H
#define CLIPMAP_IMPORT_CLI_H

/* argv[0] is "import". Returns the exit status: 0 ok, 1 runtime failure, 2 bad usage or input. */
int import_cli(int argc, char **argv);

#endif
