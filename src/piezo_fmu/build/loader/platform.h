/*
 * The platform layer of loader.c: what differs between Linux (platform_posix.c) and Windows
 * (platform_windows.c). loader.c holds the logic (the routes to Python in order, asking the
 * interpreter, the checks of its answer, the environment it gets, the statuses, the logger);
 * a platform only loads a library, runs a program once with a time limit, runs a function once
 * per process, reads and writes the environment, and lists the routes to an interpreter.
 */

#ifndef PIEZO_FMU_PLATFORM_H
#define PIEZO_FMU_PLATFORM_H

#include <stddef.h>

#define PATH_SIZE 4096
#define MAX_ROUTES 8

/* One way to an interpreter: the program and its arguments before "-c", and how a message
 * names it ("PIEZO_FMU_PYTHON=...", "python3 on PATH (/usr/bin/python3)"). */
typedef struct {
    char program[PATH_SIZE];
    const char *arguments[2]; /* NULL-terminated: "-3" for Windows' py launcher */
    char label[PATH_SIZE + 64];
} Route;

/* What the interpreter says of itself (loader.c's QUERY). */
typedef struct {
    char library[PATH_SIZE]; /* libpython*.so / python3X.dll */
    char home[PATH_SIZE];
    char packages[4 * PATH_SIZE];
    char numpy_error[512];
} PythonFacts;

/* The suffix of pythonfmu's binary beside the loader (<id>.so -> <id>.pythonfmu.so). */
extern const char PLATFORM_LIBRARY_SUFFIX[];   /* ".so" or ".dll" */
extern const char PLATFORM_REAL_SUFFIX[];      /* ".pythonfmu.so" or ".pythonfmu.dll" */
extern const char PLATFORM_PATH_SEPARATOR[];   /* ":" or ";" */
extern const char PLATFORM_DIR_SEPARATOR[];    /* "/" or "\\" */
/* The folder of a standalone FMU's own runtime under resources/python/ ("linux64", "win64"). */
extern const char PLATFORM_RUNTIME[];
/* What to set when no Python was usable. */
extern const char PLATFORM_ADVICE[];

/* Run `function` once per process, whichever thread comes first; the others wait for it. */
void platform_once(void (*function)(void));

/* The path of the loader's own binary; 0 if unknown. */
int platform_self_path(char *out, size_t size);

/* Load a library by its full path, its symbols private; NULL with `why` filled if it cannot. */
void *platform_load(const char *path, char *why, size_t why_size);
void *platform_symbol(void *library, const char *name);

/* 1 if the process has a Python already (a Python host, or an FMU loaded before). */
int platform_python_in_process(void);

/* The routes to an interpreter, in order: $PIEZO_FMU_PYTHON alone if set, else the platform's
 * own. Returns how many; `missing` says, for a message, which routes were looked for and not
 * found ("" if none was missing). */
int platform_routes(Route routes[MAX_ROUTES], char *missing, size_t missing_size);

/* Run `route` with "-c", `code` appended, stdin empty, no console, bounded by `timeout` seconds
 * (then it and its children are killed). Returns 1 with its output (stdout and stderr, malloc'd,
 * NUL-terminated), whether it timed out, and whether it exited with status 0; 0 with `why` filled
 * if it could not be run. */
int platform_run(const Route *route, const char *code, double timeout, char **output, int *timed_out,
                 int *succeeded, char *why, size_t why_size);

/* Put the interpreter of `facts` into the process, its symbols global (Linux) or its DLLs
 * preloaded by full path (Windows); 0 with `why` filled if it cannot. */
int platform_load_python(const PythonFacts *facts, char *why, size_t why_size);

/* The environment of the process (and, on Windows, of the C runtime the interpreter reads). */
/* platform_getenv: 1 and the value (cut to `size`) if `name` is set, else 0. */
int platform_getenv(const char *name, char *out, size_t size);
int platform_setenv(const char *name, const char *value);

#endif
