/*
 * The loader's platform layer on Linux (platform.h): dlopen, posix_spawn with a pipe and poll,
 * pthread_once, setenv. The routes to Python: $PIEZO_FMU_PYTHON, else python3 on PATH.
 */

#define _GNU_SOURCE /* dladdr, RTLD_DEFAULT, pipe2 */

#include "platform.h"

#include <dlfcn.h>
#include <errno.h>
#include <fcntl.h>
#include <poll.h>
#include <pthread.h>
#include <signal.h>
#include <spawn.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <time.h>
#include <unistd.h>

extern char **environ;

#define MAX_OUTPUT 65536

const char PLATFORM_LIBRARY_SUFFIX[] = ".so";
const char PLATFORM_REAL_SUFFIX[] = ".pythonfmu.so";
const char PLATFORM_PATH_SEPARATOR[] = ":";
const char PLATFORM_DIR_SEPARATOR[] = "/";
const char PLATFORM_RUNTIME[] = "linux64";
const char PLATFORM_ADVICE[] = "Set PIEZO_FMU_PYTHON=/path/to/python, a Python 3 built with --enable-shared that "
                               "can import numpy (for example a virtual environment's bin/python).";

static pthread_once_t once = PTHREAD_ONCE_INIT;
static void (*once_function)(void);

static void run_once_function(void)
{
    once_function();
}

void platform_once(void (*function)(void))
{
    once_function = function; /* the same function in every call */
    pthread_once(&once, run_once_function);
}

int platform_self_path(char *out, size_t size)
{
    Dl_info self;
    if (!dladdr((void *)&platform_self_path, &self) || !self.dli_fname) return 0;
    return (size_t)snprintf(out, size, "%s", self.dli_fname) < size;
}

void *platform_load(const char *path, char *why, size_t why_size)
{
    void *library = dlopen(path, RTLD_NOW | RTLD_LOCAL);
    if (!library) snprintf(why, why_size, "%s", dlerror());
    return library;
}

void *platform_symbol(void *library, const char *name)
{
    return dlsym(library, name);
}

int platform_python_in_process(void)
{
    return dlsym(RTLD_DEFAULT, "Py_IsInitialized") != NULL;
}

/* path of `name` in the directories of PATH (the default search path if PATH is unset) */
static int search_path(const char *name, char *out, size_t size, char *searched, size_t searched_size)
{
    const char *path = getenv("PATH");
    char fallback[256] = "";
    if (!path) {
        confstr(_CS_PATH, fallback, sizeof fallback);
        path = fallback;
    }
    snprintf(searched, searched_size, "%s%s", path, getenv("PATH") ? "" : " (PATH unset: the default)");
    while (*path) {
        size_t n = strcspn(path, ":");
        if (n > 0 && n + strlen(name) + 2 <= size) {
            snprintf(out, size, "%.*s/%s", (int)n, path, name);
            struct stat st;
            if (stat(out, &st) == 0 && S_ISREG(st.st_mode) && access(out, X_OK) == 0) return 1;
        }
        path += n + (path[n] == ':');
    }
    return 0;
}

int platform_routes(Route routes[MAX_ROUTES], char *missing, size_t missing_size)
{
    memset(routes, 0, sizeof *routes);
    missing[0] = '\0';
    const char *chosen = getenv("PIEZO_FMU_PYTHON");
    if (chosen && *chosen) {
        snprintf(routes[0].program, sizeof routes[0].program, "%s", chosen);
        snprintf(routes[0].label, sizeof routes[0].label, "PIEZO_FMU_PYTHON=%s", chosen);
        return 1;
    }
    char searched[PATH_SIZE];
    if (!search_path("python3", routes[0].program, sizeof routes[0].program, searched, sizeof searched)) {
        snprintf(missing, missing_size, "PIEZO_FMU_PYTHON is unset and there is no python3 on PATH=%s", searched);
        return 0;
    }
    snprintf(routes[0].label, sizeof routes[0].label, "python3 on PATH (%s)", routes[0].program);
    return 1;
}

static double now_s(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}

int platform_run(const Route *route, const char *code, double timeout, char **output_out, int *timed_out_out,
                 int *succeeded, char *why, size_t why_size)
{
    const char *python = route->program;
    if (access(python, X_OK) != 0) {
        snprintf(why, why_size, "cannot run it (%s)", strerror(errno));
        return 0;
    }
    int fds[2];
    if (pipe2(fds, O_CLOEXEC) != 0) {
        snprintf(why, why_size, "cannot make a pipe (%s)", strerror(errno));
        return 0;
    }
    posix_spawn_file_actions_t actions;
    posix_spawn_file_actions_init(&actions);
    posix_spawn_file_actions_addopen(&actions, 0, "/dev/null", O_RDONLY, 0);
    posix_spawn_file_actions_adddup2(&actions, fds[1], 1);
    posix_spawn_file_actions_adddup2(&actions, fds[1], 2);
    posix_spawnattr_t attributes;
    posix_spawnattr_init(&attributes);
    sigset_t all, none;
    sigfillset(&all);
    sigemptyset(&none);
    posix_spawnattr_setsigdefault(&attributes, &all); /* whatever the host's handlers */
    posix_spawnattr_setsigmask(&attributes, &none);
    posix_spawnattr_setflags(&attributes, POSIX_SPAWN_SETSIGDEF | POSIX_SPAWN_SETSIGMASK);
    char *argv[5];
    int argc = 0;
    argv[argc++] = (char *)python;
    for (int i = 0; i < 2 && route->arguments[i]; i++) argv[argc++] = (char *)route->arguments[i];
    argv[argc++] = "-c";
    argv[argc++] = (char *)code;
    argv[argc] = NULL;
    pid_t pid;
    int spawned = posix_spawn(&pid, python, &actions, &attributes, argv, environ);
    posix_spawn_file_actions_destroy(&actions);
    posix_spawnattr_destroy(&attributes);
    close(fds[1]);
    if (spawned != 0) {
        close(fds[0]);
        snprintf(why, why_size, "cannot run it (%s)", strerror(spawned));
        return 0;
    }

    char *output = malloc(MAX_OUTPUT + 1);
    size_t length = 0;
    int timed_out = 0;
    double deadline = now_s() + timeout;
    while (output) {
        double left = deadline - now_s();
        if (left <= 0) {
            timed_out = 1;
            break;
        }
        struct pollfd pfd = {fds[0], POLLIN, 0};
        int ready = poll(&pfd, 1, (int)(left * 1000.0) + 1);
        if (ready < 0 && errno == EINTR) continue;
        if (ready <= 0) continue;
        char buffer[4096];
        ssize_t n = read(fds[0], buffer, sizeof buffer);
        if (n < 0 && errno == EINTR) continue;
        if (n <= 0) break;
        size_t keep = (size_t)n < MAX_OUTPUT - length ? (size_t)n : MAX_OUTPUT - length;
        memcpy(output + length, buffer, keep);
        length += keep;
    }
    close(fds[0]);
    /* Its output has ended; it gets until the deadline to exit too. */
    int wstatus = 0;
    pid_t waited = 0;
    while (!timed_out && output) {
        waited = waitpid(pid, &wstatus, WNOHANG);
        if (waited != 0 && !(waited < 0 && errno == EINTR)) break; /* it exited, or is not ours to wait for */
        if (now_s() >= deadline) timed_out = 1;
        else poll(NULL, 0, 10);
    }
    if (timed_out || !output) {
        kill(pid, SIGKILL);
        do waited = waitpid(pid, &wstatus, 0);
        while (waited < 0 && errno == EINTR);
    }
    if (!output) {
        snprintf(why, why_size, "out of memory");
        return 0;
    }
    output[length] = '\0';
    *output_out = output;
    *timed_out_out = timed_out;
    /* not ours to wait for (the host reaps its children): judged by its answer alone */
    *succeeded = waited != pid || (WIFEXITED(wstatus) && WEXITSTATUS(wstatus) == 0);
    if (!*succeeded && WIFSIGNALED(wstatus)) snprintf(why, why_size, "killed by a signal");
    else if (!*succeeded) snprintf(why, why_size, "it failed");
    return 1;
}

int platform_load_python(const PythonFacts *facts, char *why, size_t why_size)
{
    if (dlopen(facts->library, RTLD_NOW | RTLD_GLOBAL)) return 1;
    snprintf(why, why_size, "cannot load %s (%s)", facts->library, dlerror());
    return 0;
}

int platform_getenv(const char *name, char *out, size_t size)
{
    const char *value = getenv(name);
    if (!value) return 0;
    snprintf(out, size, "%s", value);
    return 1;
}

int platform_setenv(const char *name, const char *value)
{
    return setenv(name, value, 1) == 0;
}
