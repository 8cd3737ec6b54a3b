/* N libmodbus TCP clients, each reading holding registers back to back for SECONDS; every
 * answer counted, every error counted. Prints one JSON line: clients, answers, errors,
 * answers_per_s. Builds against libmodbus (the trial's static build or Debian's libmodbus-dev):
 *   cc -O2 -I$INC benches/lmb_load.c $LIB/libmodbus.a -o lmb_load
 * usage: lmb_load HOST PORT UNIT holding|input ADDRESS COUNT CLIENTS SECONDS */
#include <modbus.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <sys/wait.h>
#include <time.h>
#include <unistd.h>

static double now(void) {
    struct timespec t;
    clock_gettime(CLOCK_MONOTONIC, &t);
    return t.tv_sec + t.tv_nsec / 1e9;
}

int main(int argc, char **argv) {
    if (argc != 9) {
        fprintf(stderr, "usage: %s HOST PORT UNIT holding|input ADDRESS COUNT CLIENTS SECONDS\n", argv[0]);
        return 2;
    }
    const char *host = argv[1];
    int port = atoi(argv[2]), unit = atoi(argv[3]), addr = atoi(argv[5]), count = atoi(argv[6]);
    int input = argv[4][0] == 'i';
    int clients = atoi(argv[7]);
    double seconds = atof(argv[8]);
    int fds[256][2];
    if (clients < 1 || clients > 256 || count < 1 || count > 125) return 2;
    for (int c = 0; c < clients; c++) {
        if (pipe(fds[c]) != 0) return 1;
        if (fork() == 0) {
            long ok = 0, bad = 0;
            uint16_t regs[125];
            modbus_t *ctx = modbus_new_tcp(host, port);
            modbus_set_slave(ctx, unit);
            if (modbus_connect(ctx) == 0) {
                double end = now() + seconds;
                while (now() < end) {
                    int rc = input ? modbus_read_input_registers(ctx, addr, count, regs)
                                   : modbus_read_registers(ctx, addr, count, regs);
                    if (rc == count) ok++; else bad++;
                }
            } else {
                bad = 1;
            }
            long out[2] = {ok, bad};
            if (write(fds[c][1], out, sizeof out) != sizeof out) _exit(1);
            _exit(0);
        }
    }
    long ok = 0, bad = 0;
    for (int c = 0; c < clients; c++) {
        long in[2] = {0, 0};
        if (read(fds[c][0], in, sizeof in) == sizeof in) { ok += in[0]; bad += in[1]; }
        wait(NULL);
    }
    printf("{\"clients\": %d, \"answers\": %ld, \"errors\": %ld, \"answers_per_s\": %.0f}\n", clients, ok, bad,
           ok / seconds);
    return bad ? 1 : 0;
}
