/* A stand-in for libonnxruntime in the bad-input tests (docs/reliability.md): it exports
 * OrtGetApiBase, whose GetVersionString returns FAKE_ORT_VERSION and whose GetApi returns NULL
 * (no API at any level), as an old or a broken build would. Built by
 * tests/test_bad_input_files.py and crates/affcorr/tests/bad_input_ort.rs with
 *   cc -shared -fPIC -DFAKE_ORT_VERSION='"1.10.0"' -o libonnxruntime.so.1.10.0 fake_ort.c
 */
#include <stddef.h>
#include <stdint.h>

static const void *get_api(uint32_t version) {
    (void)version;
    return NULL;
}

static const char *version_string(void) { return FAKE_ORT_VERSION; }

static const struct {
    const void *(*get_api)(uint32_t);
    const char *(*get_version_string)(void);
} base = {get_api, version_string};

const void *OrtGetApiBase(void) { return &base; }
