/*
 * A TCG plugin for QEMU 7.2 (plugin API version 1) that counts, per guest instruction address, how
 * often it ran, how many of its memory accesses went to a device (each one a trip out of the
 * translated code under -icount), how many translation blocks started there and how often it was
 * translated. It writes INSNCOUNT_OUT (one line per address: address, runs, device accesses, blocks
 * started, translations, disassembly) every second and at exit. The API's declarations are written
 * out below: Debian's QEMU ships no qemu-plugin.h. Used for docs/qemu.md "Critical sections and
 * dropped records"; see the qemu-system-arm wrapper beside it.
 */
#include <stdint.h>
#include <stdbool.h>
#include <stdio.h>
#include <stdlib.h>
#include <pthread.h>
#include <unistd.h>
typedef uint64_t qemu_plugin_id_t;
typedef struct qemu_info_t qemu_info_t;
struct qemu_plugin_tb; struct qemu_plugin_insn; struct qemu_plugin_hwaddr;
typedef uint32_t qemu_plugin_meminfo_t;
enum qemu_plugin_op { QEMU_PLUGIN_INLINE_ADD_U64 };
enum qemu_plugin_mem_rw { QEMU_PLUGIN_MEM_R = 1, QEMU_PLUGIN_MEM_W, QEMU_PLUGIN_MEM_RW };
enum qemu_plugin_cb_flags { QEMU_PLUGIN_CB_NO_REGS, QEMU_PLUGIN_CB_R_REGS, QEMU_PLUGIN_CB_RW_REGS };
typedef void (*mem_cb_t)(unsigned int, qemu_plugin_meminfo_t, uint64_t, void *);
void qemu_plugin_register_vcpu_tb_trans_cb(qemu_plugin_id_t id, void (*cb)(qemu_plugin_id_t, struct qemu_plugin_tb *));
size_t qemu_plugin_tb_n_insns(const struct qemu_plugin_tb *tb);
uint64_t qemu_plugin_tb_vaddr(const struct qemu_plugin_tb *tb);
struct qemu_plugin_insn *qemu_plugin_tb_get_insn(const struct qemu_plugin_tb *tb, size_t idx);
uint64_t qemu_plugin_insn_vaddr(const struct qemu_plugin_insn *insn);
char *qemu_plugin_insn_disas(const struct qemu_plugin_insn *insn);
void qemu_plugin_register_vcpu_insn_exec_inline(struct qemu_plugin_insn *, enum qemu_plugin_op, void *, uint64_t);
void qemu_plugin_register_vcpu_tb_exec_inline(struct qemu_plugin_tb *, enum qemu_plugin_op, void *, uint64_t);
void qemu_plugin_register_vcpu_mem_cb(struct qemu_plugin_insn *, mem_cb_t, enum qemu_plugin_cb_flags, enum qemu_plugin_mem_rw, void *);
struct qemu_plugin_hwaddr *qemu_plugin_get_hwaddr(qemu_plugin_meminfo_t info, uint64_t vaddr);
bool qemu_plugin_hwaddr_is_io(const struct qemu_plugin_hwaddr *haddr);
void qemu_plugin_register_atexit_cb(qemu_plugin_id_t id, void (*cb)(qemu_plugin_id_t, void *), void *);
void qemu_plugin_outs(const char *string);
__attribute__((visibility("default"))) int qemu_plugin_version = 1;

struct rec { uint64_t vaddr; uint64_t count; uint64_t io; uint64_t tbstart; uint64_t tbcount; uint64_t translations; char *disas; };
#define NB (1<<20)
static struct rec *tab[NB];
static pthread_mutex_t lock = PTHREAD_MUTEX_INITIALIZER;
static struct rec *lookup(uint64_t va, int make, struct qemu_plugin_insn *insn){ size_t h=(va*2654435761u)&(NB-1); while(tab[h]){ if(tab[h]->vaddr==va) return tab[h]; h=(h+1)&(NB-1);} if(!make) return 0; struct rec*r=calloc(1,sizeof *r); r->vaddr=va; r->disas=qemu_plugin_insn_disas(insn); tab[h]=r; return r; }

static void mem_cb(unsigned int v, qemu_plugin_meminfo_t info, uint64_t vaddr, void *ud) {
    struct qemu_plugin_hwaddr *h = qemu_plugin_get_hwaddr(info, vaddr);
    if (h && qemu_plugin_hwaddr_is_io(h)) ((struct rec *)ud)->io++;
}
static void dump(void) {
    const char *path = getenv("INSNCOUNT_OUT");
    if (!path) return;
    char tmp[4096]; snprintf(tmp, sizeof tmp, "%s.tmp", path);
    FILE *f = fopen(tmp, "w");
    if (!f) return;
    for (size_t i = 0; i < NB; i++) { struct rec *r = tab[i]; if (!r) continue;
        fprintf(f, "%08lx %12lu %10lu %10lu %4lu  %s\n", (unsigned long)r->vaddr, (unsigned long)r->count, (unsigned long)r->io, (unsigned long)r->tbcount, (unsigned long)r->translations, r->disas); }
    fclose(f); rename(tmp, path);
}
static void tb_trans(qemu_plugin_id_t id, struct qemu_plugin_tb *tb) {
    size_t n = qemu_plugin_tb_n_insns(tb);
    pthread_mutex_lock(&lock);
    for (size_t i = 0; i < n; i++) {
        struct qemu_plugin_insn *insn = qemu_plugin_tb_get_insn(tb, i);
        uint64_t va = qemu_plugin_insn_vaddr(insn);
        struct rec *r = lookup(va, 1, insn);
        if (i == 0) { r->translations++; qemu_plugin_register_vcpu_tb_exec_inline(tb, QEMU_PLUGIN_INLINE_ADD_U64, &r->tbcount, 1); }
        qemu_plugin_register_vcpu_insn_exec_inline(insn, QEMU_PLUGIN_INLINE_ADD_U64, &r->count, 1);
        qemu_plugin_register_vcpu_mem_cb(insn, mem_cb, QEMU_PLUGIN_CB_NO_REGS, QEMU_PLUGIN_MEM_RW, r);
    }
    pthread_mutex_unlock(&lock);
    /* dump now and then: the process may be killed */
}
static void *dumper(void *p){ for(;;){ sleep(1); dump(); } return 0; }
static void at_exit(qemu_plugin_id_t id, void *p) { dump(); }
__attribute__((visibility("default"))) int qemu_plugin_install(qemu_plugin_id_t id, const qemu_info_t *info, int argc, char **argv) {
    qemu_plugin_register_vcpu_tb_trans_cb(id, tb_trans);
    qemu_plugin_register_atexit_cb(id, at_exit, NULL);
    pthread_t t; pthread_create(&t, 0, dumper, 0);
    return 0;
}
