/*
 * Stand-ins that tests/test_windows.py builds with mingw-w64, for what the registries do not have:
 *
 * -DHANG               a python.exe that never answers (the loader must kill it at its deadline);
 * -DPYTHON="Z:\\..."   a py launcher: given "-3" first, it runs that python.exe with the rest of
 *                      its command line, as written, and returns its exit code (the real launcher,
 *                      py.exe, comes with Python's Windows installer, which no registry serves).
 */

#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <windows.h>

int main(void)
{
#ifdef HANG
    Sleep(600000);
    return 0;
#else
    const char *line = GetCommandLineA();
    const char *rest = strstr(line, "\"-3\"");
    if (!rest) return 2;
    rest += 4;
    size_t size = strlen(PYTHON) + strlen(rest) + 3;
    char *command = malloc(size);
    if (!command) return 2;
    snprintf(command, size, "\"%s\"%s", PYTHON, rest);
    STARTUPINFOA startup = {0};
    startup.cb = sizeof startup;
    startup.dwFlags = STARTF_USESTDHANDLES;
    startup.hStdInput = GetStdHandle(STD_INPUT_HANDLE);
    startup.hStdOutput = GetStdHandle(STD_OUTPUT_HANDLE);
    startup.hStdError = GetStdHandle(STD_ERROR_HANDLE);
    PROCESS_INFORMATION process;
    if (!CreateProcessA(PYTHON, command, NULL, NULL, TRUE, 0, NULL, NULL, &startup, &process)) return 3;
    WaitForSingleObject(process.hProcess, INFINITE);
    DWORD code = 1;
    GetExitCodeProcess(process.hProcess, &code);
    return (int)code;
#endif
}
