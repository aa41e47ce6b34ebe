/* Chimera command interpreter: the paper's library for building custom
 * command lines. A program registers commands with usage and help text;
 * the library parses lines into words, finds the command (a unique prefix
 * of a name runs it, as in many debuggers), suggests the closest name for
 * a mistyped one, runs script files, shows help (from the registered text
 * and optional help files), escapes to the shell when allowed, and reads
 * lines interactively with editing, history and tab completion (libedit;
 * built without it, plain line reading). The Chimera console is built on
 * it; so can a user's own program be.
 *
 * Lines. Words are separated by blanks (space, tab, CR, LF, VT, FF).
 * Outside quotes a backslash takes the next character literally ('\ ' is
 * a space inside a word). 'single quotes' keep everything literally up to
 * the next single quote. "double quotes" keep everything except these
 * escapes: \" \\ \n (newline) \t (tab); any other backslash sequence is an
 * error. Quoted and unquoted parts next to each other make one word
 * (a"b c"d is 'ab cd'); "" is an empty word. A '#' at the start of a word
 * begins a comment to the end of the line. Errors name the 1-based byte
 * column: "unterminated double quote opened at column 7", "unknown escape
 * '\q' in double quotes at column 4", "backslash at the end of the line
 * (column 9)". A line that starts (after blanks) with '!' is a shell
 * escape: the rest of it, unparsed, goes to /bin/sh -c when the program
 * allowed it (chm_cmdi_allow_shell), and is refused otherwise.
 *
 * Commands. The first word names a command: exactly, or by a prefix that
 * only one command name starts with. An ambiguous prefix is an error that
 * lists the candidates; an unknown word is an error that suggests the
 * closest name within a small edit distance ("unknown command 'stauts';
 * did you mean 'status'?"). The command gets argc/argv (argv[0] its full
 * name, argv[argc] NULL; the strings may be modified) and returns 0 for
 * success or a nonzero status, by convention a negative errno; it reports
 * why with chm_cmdi_error and writes its output with chm_cmdi_printf.
 * Built in: help [CMD], source FILE, history, quit and exit (the same).
 *
 * Statuses: 0 or a negative errno, unless said otherwise. After an error,
 * chm_cmdi_last_error(c) says what was wrong. A chm_cmdi_t is used by one
 * thread at a time; one interactive session (chm_cmdi_loop or
 * chm_cmdi_interactive_begin) runs in a process at a time, since libedit's
 * line editor is one per process. */
#ifndef CHIMERA_CMDI_H
#define CHIMERA_CMDI_H

#include "chimera/status.h"

#include <stddef.h>
#include <stdio.h>

#ifdef __cplusplus
extern "C" {
#endif

typedef struct chm_cmdi chm_cmdi_t;

/* A command: argv[0] is its full name, argv[argc] is NULL. Returns 0 on
 * success, nonzero (by convention a negative errno) on failure. */
typedef int (*chm_cmdi_fn)(chm_cmdi_t* c, int argc, char** argv, void* user);

/* Limits: command name length; nesting of `source` (a script sourcing a
 * script...); entries kept in the history. */
#define CHM_CMDI_NAME_MAX 63
#define CHM_CMDI_SOURCE_DEPTH 8
#define CHM_CMDI_HISTORY_MAX 1000

/* A new interpreter named `name` (letters, digits, '_', '-', '.', at most
 * CHM_CMDI_NAME_MAX bytes; libedit's name for it, and the prefix of the
 * errors chm_cmdi_loop prints), with the built-in commands registered.
 * NULL on error, with errno EINVAL (bad name) or ENOMEM. */
chm_cmdi_t* chm_cmdi_create(const char* name);

/* Free an interpreter (NULL: nothing). Ends its interactive session if
 * one is running, without saving the history. */
void chm_cmdi_destroy(chm_cmdi_t* c);

/* What the last failing call on `c` said (or a command said through
 * chm_cmdi_error), or "" when nothing failed yet. NULL c: "". */
const char* chm_cmdi_last_error(const chm_cmdi_t* c);

/* For commands: set the last-error text to the printf-formatted message
 * and return `status` (so `return chm_cmdi_error(c, -ERANGE, "...")`).
 * Returns -EINVAL for NULL c or fmt. */
CHM_CHECK int chm_cmdi_error(chm_cmdi_t* c, int status, const char* fmt, ...)
#if defined(__GNUC__)
    __attribute__((format(printf, 3, 4)))
#endif
    ;

/* Register command `name` (same characters as an interpreter name, not
 * starting with '-' or '.'; at most CHM_CMDI_NAME_MAX bytes) calling
 * fn(c, argc, argv, user). `usage` is the argument synopsis ("FILE
 * [COUNT]"; NULL: none), `help` its description, whose first line is what
 * `help` lists (NULL: none). The strings are copied. Errors: -EINVAL NULL
 * c or fn, or a bad name (the message says what is wrong with it);
 * -EEXIST a command of that name exists (built-ins included); -ENOMEM. */
CHM_CHECK int chm_cmdi_add(chm_cmdi_t* c, const char* name, chm_cmdi_fn fn, void* user, const char* usage,
                 const char* help);

/* Where commands' output (chm_cmdi_printf), help, history and the errors
 * chm_cmdi_loop prints go, and where a shell escape's stdout and stderr
 * go when `out` has a file descriptor (NULL: stdout, the default). The
 * stream stays the caller's. Errors: -EINVAL NULL c. */
CHM_CHECK int chm_cmdi_set_output(chm_cmdi_t* c, FILE* out);

/* printf to the output stream. Returns the number of bytes written, or
 * -EINVAL (NULL c or fmt) or -EIO (the stream failed). */
int chm_cmdi_printf(chm_cmdi_t* c, const char* fmt, ...)
#if defined(__GNUC__)
    __attribute__((format(printf, 2, 3)))
#endif
    ;

/* Allow (on = 1) or refuse (0, the default) the shell escape "!cmd".
 * Errors: -EINVAL NULL c or on not 0/1. */
CHM_CHECK int chm_cmdi_allow_shell(chm_cmdi_t* c, int on);

/* Scripts stop at their first failing line (on = 0, the default) or go on
 * (1), printing each failure to the output stream and returning the
 * first one's status. Errors: -EINVAL NULL c or on not 0/1. */
CHM_CHECK int chm_cmdi_keep_going(chm_cmdi_t* c, int on);

/* Where `help TOPIC` finds longer help (NULL: nowhere, the default). A
 * directory: the file TOPIC.help in it. A file: its section for TOPIC,
 * from a line "[TOPIC]" to the next line starting with '['. The text is
 * printed after the command's usage and help; a topic that is not a
 * command may have help of its own. Checked now: Errors: -EINVAL NULL c;
 * -ENOENT no such file or directory; other -errno of stat. */
CHM_CHECK int chm_cmdi_help_path(chm_cmdi_t* c, const char* path);

/* The command name closest to `word`, copied into buf (len bytes, NUL
 * included). Closeness is the Damerau-Levenshtein distance (optimal string
 * alignment: insertions, deletions, substitutions, swaps of adjacent
 * bytes) ignoring ASCII case; it must be at most 1 for words of up to 4
 * bytes, 2 up to 8, 3 beyond, and less than the word's length. Among
 * equally close names: the nearest in length, then the alphabetically
 * first. Errors: -EINVAL NULL argument; -ENOENT no name is
 * close enough; -ENAMETOOLONG it does not fit. */
CHM_CHECK int chm_cmdi_suggest(chm_cmdi_t* c, const char* word, char* buf, size_t len);

/* Parse and run one line (a blank or comment line does nothing and
 * returns 0). Returns the command's status, the shell's exit status for
 * "!cmd" (128 + N when killed by signal N), or: -EINVAL a syntax error
 * (the message names the column) or NULL argument; -ENOENT unknown
 * command (with a suggestion when one is close); -ENOTUNIQ ambiguous
 * prefix (the candidates listed); -EPERM a shell escape that is not
 * allowed; another -errno when /bin/sh cannot be started; -ELOOP commands
 * running lines nested 32 deep; -ENOMEM. When a
 * command fails without calling chm_cmdi_error the message says which
 * command returned what. */
CHM_CHECK int chm_cmdi_run_line(chm_cmdi_t* c, const char* line);

/* Run `len` bytes of text (need not end in NUL) as a script named `name`
 * (NULL: "<string>"): line by line ('\n' ends a line, a '\r' before it is
 * dropped), stopping at the first failing line unless chm_cmdi_keep_going;
 * `quit` stops the script (and the interactive session running it).
 * Returns 0 or the failing line's status, its message prefixed with
 * "name:line: " (a nested script adds its own: "a.cmd:3: b.cmd:1: ...").
 * Errors besides a line's: -EINVAL NULL c, or text NULL with len > 0, or
 * a NUL byte in a line; -ELOOP scripts nested deeper than
 * CHM_CMDI_SOURCE_DEPTH. */
CHM_CHECK int chm_cmdi_run_text(chm_cmdi_t* c, const char* text, size_t len, const char* name);

/* Run the script file at `path` (at most 16 MiB, a regular file: not a
 * device or pipe that could block or never end), as chm_cmdi_run_text
 * naming it by `path`; `source FILE` does this. A relative path is
 * relative to the working directory. Errors besides a line's: -EINVAL;
 * -ENOENT; -EACCES; -EISDIR; -EFBIG; other -errno of open/read; -ELOOP. */
CHM_CHECK int chm_cmdi_run_script(chm_cmdi_t* c, const char* path);

/* Add a line to the history (blank lines and a repeat of the last entry
 * are not added; beyond CHM_CMDI_HISTORY_MAX the oldest entry goes).
 * Interactive sessions add each line they read. Errors: -EINVAL NULL
 * argument or a line holding '\n'; -ENOMEM. */
CHM_CHECK int chm_cmdi_history_add(chm_cmdi_t* c, const char* line);

/* Keep the history in the file at `path`: its lines are added to the
 * history now (a missing file is an empty history), and the history is
 * written back there by chm_cmdi_history_save, which chm_cmdi_loop and
 * chm_cmdi_interactive_end call. One entry per line, plain text.
 * Errors: -EINVAL NULL or empty path; the errors of reading it as for
 * chm_cmdi_run_script (message "history file: ..."). */
CHM_CHECK int chm_cmdi_history_file(chm_cmdi_t* c, const char* path);

/* Write the history to the file of chm_cmdi_history_file (replacing it
 * whole, by renaming a temporary file beside it). Errors: -EINVAL NULL c;
 * -ENOENT no history file was set; other -errno of writing it. */
CHM_CHECK int chm_cmdi_history_save(chm_cmdi_t* c);

/* Returns 1 when the library was built with libedit (line editing, tab
 * completion), 0 when interactive sessions read plain lines. Never fails. */
int chm_cmdi_has_line_editing(void);

/* Read lines from stdin and run them until quit or end of input,
 * printing `prompt` (NULL: "NAME> ") and each failing line's message
 * ("NAME: message") to the output stream. On a terminal, with libedit:
 * line editing, history (up/down), tab completion of command names (and
 * of file names after the first word). Saves the history when a file was
 * set. Returns 0, or: -EINVAL NULL c; -EBUSY another session is running;
 * -EIO reading stdin failed; the errors of chm_cmdi_history_save. */
CHM_CHECK int chm_cmdi_loop(chm_cmdi_t* c, const char* prompt);

/* The same session driven by the caller, for a program that also waits on
 * other descriptors (the console prints remote tasks' output while the
 * user edits a line): begin shows the prompt; call step whenever stdin
 * (fd 0) is readable: it reads what is there without blocking for more
 * and runs each line completed; print_async shows text above the line
 * being edited and redraws it; end restores the terminal and saves the
 * history. begin errors: -EINVAL NULL c; -EBUSY a session is running.
 * step returns 0 while the session goes on, 1 once it is over (quit or
 * end of input; call end), or -EINVAL (no session of c), -EIO. Errors of
 * lines are printed, as by chm_cmdi_loop, not returned. */
CHM_CHECK int chm_cmdi_interactive_begin(chm_cmdi_t* c, const char* prompt);
CHM_CHECK int chm_cmdi_interactive_step(chm_cmdi_t* c);

/* Print `text` (a newline is added when it lacks one) to stdout above the
 * line being edited, which is redrawn after it (with libedit; plain
 * reading shows the prompt again, the half-typed line stays with the
 * terminal); outside a session of c, print it to the output stream.
 * Errors: -EINVAL NULL argument; -EIO. */
CHM_CHECK int chm_cmdi_print_async(chm_cmdi_t* c, const char* text);

/* End c's interactive session: restore the terminal, save the history
 * (when a file was set). Errors: -EINVAL NULL c or no session of c; the
 * errors of chm_cmdi_history_save (the session is ended all the same). */
CHM_CHECK int chm_cmdi_interactive_end(chm_cmdi_t* c);

/* Ask the session (or the script) running c's lines to stop after the
 * current line, as the built-in quit does; called between lines, the
 * next chm_cmdi_interactive_step returns 1 without reading. Errors:
 * -EINVAL NULL c. */
CHM_CHECK int chm_cmdi_quit(chm_cmdi_t* c);

#ifdef __cplusplus
}
#endif

#endif
