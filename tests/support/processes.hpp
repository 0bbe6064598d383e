#pragma once
// Processes for tests of what dead runs leave behind.
#include <sys/wait.h>
#include <unistd.h>

namespace tigerlod::testing {

/// The id of a process that has exited and been reaped: a "dead run".
inline pid_t dead_pid()
{
    const pid_t pid = ::fork();
    if (pid == 0) {
        ::_exit(0);
    }
    int status = 0;
    ::waitpid(pid, &status, 0);
    return pid;
}

} // namespace tigerlod::testing
