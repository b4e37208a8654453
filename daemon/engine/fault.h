/* fault — how the engine tells its program about a failure nobody asked about (a file node's
 * read failing at run time): the engine does not log (docs/ARCHITECTURE.md), it hands one
 * line to the sink its program installed (clipmapd: its log, as a warning). Without a sink
 * the line goes to stderr. Callers report each distinct fault once (e.g. once per file), so
 * this is never a flood. Thread-safe. */
#ifndef CLIPMAP_ENGINE_FAULT_H
#define CLIPMAP_ENGINE_FAULT_H

typedef void (*engine_fault_fn)(const char *line);

/* Installs fn (NULL: stderr). Call from main before threads start. */
void engine_fault_sink(engine_fault_fn fn);
/* Formats one line (no newline) and hands it to the sink. */
void engine_fault(const char *fmt, ...) __attribute__((format(printf, 1, 2)));

#endif
