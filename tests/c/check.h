/* The C test programs' one assertion: counts passes and failures, and on a failure prints
 * where, why and libikid's last error. Each program ends with
 * printf("%d passed, %d failed\n", passed, failed). */
#ifndef IKID_TESTS_CHECK_H
#define IKID_TESTS_CHECK_H

#include <stdio.h>

#include "ikid.h"

static int passed = 0, failed = 0;

#define CHECK(cond, ...)                                             \
    do {                                                             \
        if (cond) {                                                  \
            passed++;                                                \
        } else {                                                     \
            failed++;                                                \
            fprintf(stderr, "FAIL %s:%d: ", __FILE__, __LINE__);     \
            fprintf(stderr, __VA_ARGS__);                            \
            fprintf(stderr, " (last error: %s)\n", ikid_last_error()); \
        }                                                            \
    } while (0)

#endif
