/* FNV-1a, 64 bits (Fowler, Noll & Vo): the one hash of scenes, reference
 * keys and checkpoint records.  Not cryptographic: it names and checks
 * files, it does not defend them. */
#ifndef RP_HASH_H
#define RP_HASH_H

#include <stddef.h>
#include <stdint.h>

#define RP_FNV1A64_INIT UINT64_C(0xcbf29ce484222325)

/* h updated with n bytes (start from RP_FNV1A64_INIT). */
uint64_t rp_fnv1a64(uint64_t h, const void *data, size_t n);

#endif
