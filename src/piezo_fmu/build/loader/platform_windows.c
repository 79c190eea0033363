/*
 * The loader's platform layer on Windows (platform.h), cross-compiled with mingw-w64:
 * LoadLibraryExA, CreateProcessA in a job object with a pipe, InitOnceExecuteOnce, the process's
 * environment and that of the C runtime the interpreter reads (ucrtbase.dll).
 *
 * The routes to Python: %PIEZO_FMU_PYTHON%, else the py launcher (py -3), python.exe on PATH,
 * and the PEP 514 registry entries (HKCU, then HKLM: Software\Python\PythonCore\<version>, the
 * newest version first). pythonfmu's binary imports python3.dll, which forwards to python3X.dll:
 * both are loaded by full path before it, python3X.dll first.
 */

#define _WIN32_WINNT 0x0601 /* Windows 7: K32EnumProcessModules in kernel32 */
#define PSAPI_VERSION 2

#include "platform.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <windows.h>
#include <psapi.h>

#define MAX_OUTPUT 65536
#define PYTHON_CORE "Software\\Python\\PythonCore"

const char PLATFORM_LIBRARY_SUFFIX[] = ".dll";
const char PLATFORM_REAL_SUFFIX[] = ".pythonfmu.dll";
const char PLATFORM_PATH_SEPARATOR[] = ";";
const char PLATFORM_DIR_SEPARATOR[] = "\\";
const char PLATFORM_RUNTIME[] = "win64";
const char PLATFORM_ADVICE[] = "Set PIEZO_FMU_PYTHON=C:\\path\\to\\python.exe, a Python 3 that can import numpy "
                               "(for example a virtual environment's Scripts\\python.exe), or put one on PATH.";

static INIT_ONCE once = INIT_ONCE_STATIC_INIT;

static BOOL CALLBACK run_once_function(PINIT_ONCE init, PVOID function, PVOID *context)
{
    (void)init, (void)context;
    ((void (*)(void))function)();
    return TRUE;
}

void platform_once(void (*function)(void))
{
    InitOnceExecuteOnce(&once, run_once_function, (PVOID)function, NULL);
}

static void system_message(DWORD error, char *out, size_t size)
{
    char text[512] = "";
    FormatMessageA(FORMAT_MESSAGE_FROM_SYSTEM | FORMAT_MESSAGE_IGNORE_INSERTS, NULL, error, 0, text, sizeof text, NULL);
    size_t n = strlen(text);
    while (n > 0 && (text[n - 1] == '\n' || text[n - 1] == '\r' || text[n - 1] == ' ' || text[n - 1] == '.')) text[--n] = '\0';
    snprintf(out, size, "error %lu%s%s", (unsigned long)error, n ? ": " : "", text);
}

int platform_self_path(char *out, size_t size)
{
    HMODULE self;
    if (!GetModuleHandleExA(GET_MODULE_HANDLE_EX_FLAG_FROM_ADDRESS | GET_MODULE_HANDLE_EX_FLAG_UNCHANGED_REFCOUNT,
                            (LPCSTR)(void *)&platform_self_path, &self))
        return 0;
    DWORD n = GetModuleFileNameA(self, out, (DWORD)size);
    return n > 0 && n < size;
}

void *platform_load(const char *path, char *why, size_t why_size)
{
    HMODULE library = LoadLibraryExA(path, NULL, LOAD_WITH_ALTERED_SEARCH_PATH);
    if (!library) system_message(GetLastError(), why, why_size);
    return (void *)library;
}

void *platform_symbol(void *library, const char *name)
{
    return (void *)GetProcAddress((HMODULE)library, name);
}

/* The process's modules, in a malloc'd array; NULL if they cannot be listed. */
static HMODULE *process_modules(DWORD *count)
{
    DWORD needed = 0;
    HMODULE *modules = NULL;
    for (int attempt = 0; attempt < 4; attempt++) {
        DWORD size = needed ? needed + 16 * sizeof(HMODULE) : 256 * sizeof(HMODULE);
        HMODULE *grown = realloc(modules, size);
        if (!grown) break;
        modules = grown;
        if (!K32EnumProcessModules(GetCurrentProcess(), modules, size, &needed)) break;
        if (needed <= size) {
            *count = needed / sizeof(HMODULE);
            return modules;
        }
    }
    free(modules);
    return NULL;
}

/* A Python in the process is a module with Py_IsInitialized that is not python3.dll (which only
 * forwards). pythonfmu's binary imports python3.dll: it is loaded from beside that module. */
int platform_python_in_process(void)
{
    DWORD count = 0;
    HMODULE *modules = process_modules(&count);
    int found = 0;
    for (DWORD i = 0; modules && i < count && !found; i++) {
        char path[PATH_SIZE];
        DWORD n = GetModuleFileNameA(modules[i], path, sizeof path);
        if (n == 0 || n >= sizeof path || !GetProcAddress(modules[i], "Py_IsInitialized")) continue;
        char *name = strrchr(path, '\\');
        name = name ? name + 1 : path;
        if (_stricmp(name, "python3.dll") == 0) continue;
        found = 1;
        if (!GetModuleHandleA("python3.dll") && (size_t)(name - path) + sizeof "python3.dll" <= sizeof path) {
            strcpy(name, "python3.dll");
            LoadLibraryExA(path, NULL, LOAD_WITH_ALTERED_SEARCH_PATH);
        }
    }
    free(modules);
    return found;
}

static int is_file(const char *path)
{
    DWORD attributes = GetFileAttributesA(path);
    return attributes != INVALID_FILE_ATTRIBUTES && !(attributes & FILE_ATTRIBUTE_DIRECTORY);
}

/* `name` in the directories of PATH, as written there. */
static int search_path(const char *name, char *out, size_t size, char *path, size_t path_size)
{
    DWORD n = GetEnvironmentVariableA("PATH", path, (DWORD)path_size);
    if (n == 0 || n >= path_size) path[0] = '\0';
    for (const char *p = path; *p;) {
        size_t length = strcspn(p, ";");
        if (length > 0 && length + strlen(name) + 2 <= size) {
            snprintf(out, size, "%.*s\\%s", (int)length, p, name);
            if (is_file(out)) return 1;
        }
        p += length + (p[length] == ';');
    }
    return 0;
}

static int compare_versions(const void *a, const void *b)
{
    const char *x = a, *y = b;
    int major_x = 0, minor_x = 0, major_y = 0, minor_y = 0;
    sscanf(x, "%d.%d", &major_x, &minor_x);
    sscanf(y, "%d.%d", &major_y, &minor_y);
    return major_x != major_y ? major_y - major_x : minor_y - minor_x; /* newest first */
}

/* The interpreter of the newest Python 3 registered under `root` (PEP 514): its ExecutablePath,
 * else python.exe in its InstallPath. */
static int registered_python(HKEY root, char *out, size_t size)
{
    HKEY core;
    if (RegOpenKeyExA(root, PYTHON_CORE, 0, KEY_READ, &core) != ERROR_SUCCESS) return 0;
    char versions[64][64];
    DWORD count = 0;
    for (DWORD i = 0; count < 64; i++) {
        DWORD length = sizeof versions[count];
        LONG result = RegEnumKeyExA(core, i, versions[count], &length, NULL, NULL, NULL, NULL);
        if (result == ERROR_NO_MORE_ITEMS) break;
        if (result == ERROR_SUCCESS && versions[count][0] == '3') count++;
    }
    qsort(versions, count, sizeof versions[0], compare_versions);
    int found = 0;
    for (DWORD i = 0; i < count && !found; i++) {
        char key[128];
        snprintf(key, sizeof key, "%s\\InstallPath", versions[i]);
        DWORD length = (DWORD)size;
        if (RegGetValueA(core, key, "ExecutablePath", RRF_RT_REG_SZ, NULL, out, &length) == ERROR_SUCCESS &&
            is_file(out)) {
            found = 1;
            break;
        }
        length = (DWORD)size;
        if (RegGetValueA(core, key, NULL, RRF_RT_REG_SZ, NULL, out, &length) == ERROR_SUCCESS) {
            size_t n = strlen(out);
            snprintf(out + n, size - n, "%spython.exe", n && out[n - 1] == '\\' ? "" : "\\");
            found = is_file(out);
        }
    }
    RegCloseKey(core);
    return found;
}

static void append(char *text, size_t size, const char *part)
{
    size_t n = strlen(text);
    snprintf(text + n, size - n, "%s%s", n ? "; " : "", part);
}

int platform_routes(Route routes[MAX_ROUTES], char *missing, size_t missing_size)
{
    memset(routes, 0, MAX_ROUTES * sizeof *routes);
    missing[0] = '\0';
    char chosen[PATH_SIZE];
    DWORD n = GetEnvironmentVariableA("PIEZO_FMU_PYTHON", chosen, sizeof chosen);
    if (n > 0 && n < sizeof chosen) {
        snprintf(routes[0].program, sizeof routes[0].program, "%s", chosen);
        snprintf(routes[0].label, sizeof routes[0].label, "PIEZO_FMU_PYTHON=%s", chosen);
        return 1;
    }
    int count = 0;
    append(missing, missing_size, "PIEZO_FMU_PYTHON is unset");
    char *file_part;
    if (SearchPathA(NULL, "py.exe", NULL, sizeof routes[count].program, routes[count].program, &file_part)) {
        routes[count].arguments[0] = "-3";
        snprintf(routes[count].label, sizeof routes[count].label, "the py launcher (%s -3)", routes[count].program);
        count++;
    } else append(missing, missing_size, "there is no py launcher");
    static char path[32768];
    if (search_path("python.exe", routes[count].program, sizeof routes[count].program, path, sizeof path)) {
        snprintf(routes[count].label, sizeof routes[count].label, "python.exe on PATH (%s)", routes[count].program);
        count++;
    } else {
        char text[PATH_SIZE];
        snprintf(text, sizeof text, "there is no python.exe on PATH=%.3000s", path);
        append(missing, missing_size, text);
    }
    static const struct { HKEY root; const char *name; } hives[] = {{HKEY_CURRENT_USER, "HKCU"},
                                                                    {HKEY_LOCAL_MACHINE, "HKLM"}};
    for (int i = 0; i < 2; i++) {
        if (registered_python(hives[i].root, routes[count].program, sizeof routes[count].program)) {
            snprintf(routes[count].label, sizeof routes[count].label, "the registry (%s\\" PYTHON_CORE ": %s)",
                     hives[i].name, routes[count].program);
            count++;
        } else {
            char text[128];
            snprintf(text, sizeof text, "no Python 3 in %s\\" PYTHON_CORE, hives[i].name);
            append(missing, missing_size, text);
        }
    }
    return count;
}

/* One argument of a command line, quoted as CommandLineToArgvW and the C runtime read it back. */
static int quote(char *line, size_t size, size_t *at, const char *argument)
{
    size_t n = *at;
    if (n + 1 >= size) return 0;
    if (n) line[n++] = ' ';
    line[n++] = '"';
    for (const char *p = argument;; p++) {
        size_t backslashes = 0;
        while (*p == '\\') p++, backslashes++;
        size_t repeat = !*p ? 2 * backslashes : *p == '"' ? 2 * backslashes + 1 : backslashes;
        if (n + repeat + 3 >= size) return 0;
        for (size_t i = 0; i < repeat; i++) line[n++] = '\\';
        if (!*p) break;
        line[n++] = *p;
    }
    line[n++] = '"';
    line[n] = '\0';
    *at = n;
    return 1;
}

int platform_run(const Route *route, const char *code, double timeout, char **output_out, int *timed_out_out,
                 int *succeeded, char *why, size_t why_size)
{
    size_t line_size = strlen(code) * 2 + 4 * PATH_SIZE, at = 0;
    char *line = malloc(line_size);
    int quoted = line && quote(line, line_size, &at, route->program);
    for (int i = 0; quoted && i < 2 && route->arguments[i]; i++) quoted = quote(line, line_size, &at, route->arguments[i]);
    quoted = quoted && quote(line, line_size, &at, "-c") && quote(line, line_size, &at, code);
    if (!quoted) {
        free(line);
        snprintf(why, why_size, "out of memory");
        return 0;
    }

    SECURITY_ATTRIBUTES inherit = {sizeof inherit, NULL, TRUE};
    HANDLE read_end = NULL, write_end = NULL;
    HANDLE nul = CreateFileA("NUL", GENERIC_READ, FILE_SHARE_READ | FILE_SHARE_WRITE, &inherit, OPEN_EXISTING, 0, NULL);
    if (!CreatePipe(&read_end, &write_end, &inherit, 0)) {
        system_message(GetLastError(), why, why_size);
        free(line);
        if (nul != INVALID_HANDLE_VALUE) CloseHandle(nul);
        return 0;
    }
    SetHandleInformation(read_end, HANDLE_FLAG_INHERIT, 0);
    STARTUPINFOA startup = {0};
    startup.cb = sizeof startup;
    startup.dwFlags = STARTF_USESTDHANDLES;
    startup.hStdInput = nul;
    startup.hStdOutput = write_end;
    startup.hStdError = write_end;
    PROCESS_INFORMATION process = {0};
    /* A job holds it and whatever it starts (py starts python.exe): a timeout ends them all. */
    HANDLE job = CreateJobObjectA(NULL, NULL);
    JOBOBJECT_EXTENDED_LIMIT_INFORMATION limits = {0};
    limits.BasicLimitInformation.LimitFlags = JOB_OBJECT_LIMIT_KILL_ON_JOB_CLOSE;
    if (job) SetInformationJobObject(job, JobObjectExtendedLimitInformation, &limits, sizeof limits);
    BOOL created = CreateProcessA(route->program, line, NULL, NULL, TRUE, CREATE_NO_WINDOW | CREATE_SUSPENDED, NULL,
                                  NULL, &startup, &process);
    DWORD error = GetLastError();
    free(line);
    CloseHandle(write_end);
    if (nul != INVALID_HANDLE_VALUE) CloseHandle(nul);
    if (!created) {
        CloseHandle(read_end);
        if (job) CloseHandle(job);
        char text[512];
        system_message(error, text, sizeof text);
        snprintf(why, why_size, "cannot run it (%s)", text);
        return 0;
    }
    if (job) AssignProcessToJobObject(job, process.hProcess);
    ResumeThread(process.hThread);
    CloseHandle(process.hThread);

    char *output = malloc(MAX_OUTPUT + 1);
    size_t length = 0;
    int timed_out = 0;
    ULONGLONG deadline = GetTickCount64() + (ULONGLONG)(timeout * 1000.0);
    while (output) {
        if (GetTickCount64() >= deadline) {
            timed_out = 1;
            break;
        }
        DWORD available = 0;
        if (!PeekNamedPipe(read_end, NULL, 0, NULL, &available, NULL)) break; /* every writer has closed it */
        if (available == 0) {
            Sleep(5);
            continue;
        }
        char buffer[4096];
        DWORD n = 0;
        if (!ReadFile(read_end, buffer, available < sizeof buffer ? available : sizeof buffer, &n, NULL) || n == 0) break;
        size_t keep = n < MAX_OUTPUT - length ? n : MAX_OUTPUT - length;
        memcpy(output + length, buffer, keep);
        length += keep;
    }
    CloseHandle(read_end);
    /* Its output has ended; it gets until the deadline to exit too. */
    if (!timed_out) {
        ULONGLONG now = GetTickCount64();
        timed_out = WaitForSingleObject(process.hProcess, now < deadline ? (DWORD)(deadline - now) : 0) != WAIT_OBJECT_0;
    }
    DWORD code_of_exit = 1;
    if (timed_out || !output) {
        if (job) TerminateJobObject(job, 1);
        TerminateProcess(process.hProcess, 1);
        WaitForSingleObject(process.hProcess, 5000);
    } else GetExitCodeProcess(process.hProcess, &code_of_exit);
    CloseHandle(process.hProcess);
    if (job) CloseHandle(job);
    if (!output) {
        snprintf(why, why_size, "out of memory");
        return 0;
    }
    /* Python writes "\r\n" to a pipe: the answer is read with "\n" alone. */
    size_t kept = 0;
    for (size_t i = 0; i < length; i++)
        if (output[i] != '\r') output[kept++] = output[i];
    output[kept] = '\0';
    *output_out = output;
    *timed_out_out = timed_out;
    *succeeded = !timed_out && code_of_exit == 0;
    if (!*succeeded) snprintf(why, why_size, "it failed with exit code %lu", (unsigned long)code_of_exit);
    return 1;
}

int platform_load_python(const PythonFacts *facts, char *why, size_t why_size)
{
    char forwarder[PATH_SIZE], text[512];
    const char *slash = strrchr(facts->library, '\\');
    size_t folder = slash ? (size_t)(slash - facts->library) + 1 : 0;
    snprintf(forwarder, sizeof forwarder, "%.*spython3.dll", (int)folder, facts->library);
    if (!LoadLibraryExA(facts->library, NULL, LOAD_WITH_ALTERED_SEARCH_PATH)) {
        system_message(GetLastError(), text, sizeof text);
        snprintf(why, why_size, "cannot load %s (%s)", facts->library, text);
        return 0;
    }
    if (!LoadLibraryExA(forwarder, NULL, LOAD_WITH_ALTERED_SEARCH_PATH)) {
        system_message(GetLastError(), text, sizeof text);
        snprintf(why, why_size, "cannot load %s (%s)", forwarder, text);
        return 0;
    }
    return 1;
}

int platform_getenv(const char *name, char *out, size_t size)
{
    DWORD n = GetEnvironmentVariableA(name, out, (DWORD)size);
    if (n >= size) out[0] = '\0';
    return n > 0;
}

/* The interpreter reads its environment through the universal C runtime, which keeps a copy of
 * its own once it has started: that copy gets the value too. */
int platform_setenv(const char *name, const char *value)
{
    if (!SetEnvironmentVariableA(name, value)) return 0;
    HMODULE runtime = GetModuleHandleA("ucrtbase.dll");
    typedef int(__cdecl * PutenvType)(const char *, const char *);
    PutenvType putenv_s = runtime ? (PutenvType)(void *)GetProcAddress(runtime, "_putenv_s") : NULL;
    return !putenv_s || putenv_s(name, value) == 0;
}
