/*
 * _nmeascan: one pass over a block of NMEA 0183 text (the hot path of dracc.ingest.nmea).
 *
 * For each line the kernel decides whether it is "clean": no prefix or one IEC 61162-450
 * TAG block with a correct checksum, then exactly one sentence '$ttsss,...*hh' with a
 * correct two-digit checksum, a supported type with the right number of fields and every
 * field it reads well formed.  Clean lines are decoded here into per-row columns with the
 * same arithmetic as the numpy decoders of nmea.py (same operations in the same order, so
 * the same doubles).  Every other line (any rejection, other prefixes, several sentences,
 * one-digit or missing checksums, non-printable bytes, numbers beyond the exact fast
 * path, ...) is copied verbatim into a side buffer and parsed by the numpy path: the
 * kernel is at least as strict as the numpy code, never more lenient.
 *
 * Numbers: [+-]digits[.digits] (at least one digit, at most 20 bytes) converted as
 * mantissa / 10^fraction_digits, which is correctly rounded when the mantissa is below
 * 2^53 and 10^f is exact (f <= 22): Clinger (1990), "How to read floating point numbers
 * accurately", fast path.  Other numbers send the line to the numpy path.
 *
 * Lines end at LF, CR LF, CR CR LF (a CR LF written through a text-mode conversion) or a
 * lone CR (old Mac loggers, serial capture tools), exactly as nmea._line_bounds splits
 * them.  A line whose content is longer than max_line bytes is not scanned: it is listed
 * (line index, content start and end) and rejected as 'too_long' by nmea._parse_c, and
 * only its tail (from its last sentence start and TAG block in its last max_line bytes) goes
 * to the numpy path, so a damaged block costs no memory beyond its own bytes.  Fallback
 * lines are listed by their line index: no array per line of the block.
 *
 * Safety: every index is checked against the line end; the input may hold any bytes
 * (NUL, huge lines, a final line without a line end).  The scan runs without the GIL.
 * Build with -ffp-contract=off: no fused multiply-add, bit-equal to numpy.
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <math.h>
#include <stdint.h>
#include <string.h>

enum { T_HDT, T_HDM, T_HDG, T_THS, T_ROT, T_VHW, T_VBW, T_VLW, T_GGA, T_GLL, T_RMC,
       T_GNS, T_VTG, T_ZDA, NTYPES };
/* same order as nmea.SENTENCES / FIELD_COUNTS */
static const char TYPES[NTYPES][4] = {"HDT", "HDM", "HDG", "THS", "ROT", "VHW", "VBW",
                                      "VLW", "GGA", "GLL", "RMC", "GNS", "VTG", "ZDA"};
static const int FMIN[NTYPES] = {2, 2, 5, 2, 2, 8, 6, 4, 12, 4, 10, 12, 8, 4};
static const int FMAX[NTYPES] = {3, 3, 6, 3, 3, 9, 11, 9, 15, 8, 14, 14, 10, 7};
static const char GNSS[][3] = {"GP", "GN", "GL", "GA", "GB", "GI", "GQ", "BD"};

#define MAXF 16          /* commas kept per sentence (GGA has at most 15) */
#define MAXNUM 20        /* nmea parse_numbers width */
#define TAG_MAX 128      /* tagblock.TAG_ROW_BYTES */
#define MAX_SOURCE 64    /* tagblock.MAX_SOURCE_CHARS */
#define MAXNAMES 256     /* distinct TAG sources per block handled here */
#define NVAL 6           /* value columns per row */
static const int64_t MISSING_NS = INT64_MIN;

static const double KN_MPS = 1852.0 / 3600.0;  /* units.KN_MPS */
static const double NMI_M = 1852.0;            /* units.NMI_M */
static const double POW10[23] = {1e0, 1e1, 1e2, 1e3, 1e4, 1e5, 1e6, 1e7, 1e8, 1e9, 1e10,
                                 1e11, 1e12, 1e13, 1e14, 1e15, 1e16, 1e17, 1e18, 1e19,
                                 1e20, 1e21, 1e22};

static int hexval(uint8_t c) {
    if (c >= '0' && c <= '9') return c - '0';
    if (c >= 'A' && c <= 'F') return c - 'A' + 10;
    if (c >= 'a' && c <= 'f') return c - 'a' + 10;
    return -1;
}

/* A field [p, p+n) as a number.  Returns 0 for empty (NaN), 1 for a number, -1 when the
 * line must go to the numpy path (not a number there either, or beyond the fast path). */
static int parse_num(const uint8_t *p, Py_ssize_t n, double *out, int *dec) {
    *out = NAN;
    *dec = -1;
    if (n == 0) return 0;
    if (n > MAXNUM) return -1;
    Py_ssize_t i = 0;
    int neg = 0;
    if (p[0] == '+' || p[0] == '-') {
        neg = p[0] == '-';
        i = 1;
    }
    uint64_t m = 0;
    int ndig = 0, frac = -1;
    for (; i < n; i++) {
        uint8_t c = p[i];
        if (c >= '0' && c <= '9') {
            m = m * 10 + (uint64_t)(c - '0');  /* <= 20 digits of which < 2^53 checked below */
            if (m >= ((uint64_t)1 << 53)) return -1;
            ndig++;
            if (frac >= 0) frac++;
        } else if (c == '.' && frac < 0) {
            frac = 0;
        } else {
            return -1;
        }
    }
    if (ndig == 0) return -1;
    int f = frac < 0 ? 0 : frac;
    if (f > 22) return -1;
    double v = (double)m / POW10[f];  /* exact operands: one correctly rounded division */
    *out = neg ? -v : v;
    *dec = frac;
    return 1;
}

/* The fields of one sentence: field k (1-based) is [s, e) */
typedef struct {
    const uint8_t *b;
    Py_ssize_t comma[MAXF];
    int nf;
    Py_ssize_t body_end;
    int bad;  /* set when a field would be rejected (or is beyond the fast path) */
} Fields;

static Py_ssize_t flen(const Fields *F, int k, Py_ssize_t *s) {
    if (F->nf < k) {
        *s = 0;
        return 0;
    }
    *s = F->comma[k - 1] + 1;
    Py_ssize_t e = F->nf > k ? F->comma[k] : F->body_end;
    return e - *s;
}

static double fnum(Fields *F, int k, int *dec) {
    Py_ssize_t s;
    Py_ssize_t n = flen(F, k, &s);
    double v;
    int d;
    if (parse_num(F->b + s, n, &v, &d) < 0) F->bad = 1;
    if (dec) *dec = d;
    return v;
}

static int fchar(Fields *F, int k) {  /* one byte, 0 if empty; longer text is bad */
    Py_ssize_t s;
    Py_ssize_t n = flen(F, k, &s);
    if (n > 1) F->bad = 1;
    return n == 1 ? F->b[s] : 0;
}

static int ffirst(Fields *F, int k) {
    Py_ssize_t s;
    Py_ssize_t n = flen(F, k, &s);
    return n >= 1 ? F->b[s] : 0;
}

static const double DEG = 3.141592653589793 / 180.0;  /* nmea.DEG = np.pi / 180.0 */

/* ddmm.mmmm + hemisphere -> rad (nmea._latlon) */
static double latlon(Fields *F, int k, int kh, int pos, int neg, double limit, int *dec) {
    double v = fnum(F, k, dec);
    int h = fchar(F, kh);
    double deg = floor(v / 100.0);
    double minutes = v - 100.0 * deg;
    double ang = deg + minutes / 60.0;  /* ddmm.mmmm -> degrees */
    double sign = h == neg ? -1.0 : 1.0;
    if (!isnan(v) && ((h != pos && h != neg) || minutes >= 60.0 || ang > limit || v < 0)) {
        F->bad = 1;
        return NAN;
    }
    return sign * ang * DEG;
}

/* hhmmss.sss -> ns of the day, -1 if empty (nmea._tod) */
static int64_t tod(Fields *F, int k) {
    double v = fnum(F, k, NULL);
    if (isnan(v)) return -1;
    double hh = floor(v / 10000.0);
    double mm = floor(v / 100.0) - 100.0 * hh;
    double ss = v - 10000.0 * hh - 100.0 * mm;
    if (hh >= 24 || mm >= 60 || ss >= 61 || v < 0) {
        F->bad = 1;
        return -1;
    }
    int64_t us = (int64_t)nearbyint(ss * 1e6);  /* np.round: half to even */
    return ((int64_t)(hh * 3600 + mm * 60) * 1000000 + us) * 1000;
}

static int64_t floordiv(int64_t a, int64_t b) {
    int64_t q = a / b;
    if ((a % b != 0) && ((a < 0) != (b < 0))) q--;
    return q;
}

/* timebase.valid_civil + days_from_civil (Hinnant); -1 if any part is empty */
static int64_t ymd_days(Fields *F, double y, double m, double d) {
    if (isnan(y) || isnan(m) || isnan(d)) return -1;
    if (!(fabs(y) < 1e9 && fabs(m) < 1e9 && fabs(d) < 1e9)) {  /* numpy wraps: leave it there */
        F->bad = 1;
        return -1;
    }
    int64_t yi = (int64_t)y, mi = (int64_t)m, di = (int64_t)d;
    static const int mdays[12] = {31, 28, 31, 30, 31, 30, 31, 31, 30, 31, 30, 31};
    if (mi < 1 || mi > 12) {
        F->bad = 1;
        return -1;
    }
    int leap = ((yi % 4 == 0) && (yi % 100 != 0)) || (yi % 400 == 0);
    int dim = mdays[mi - 1] + (mi == 2 && leap);
    if (di < 1 || di > dim) {
        F->bad = 1;
        return -1;
    }
    int64_t yy = yi - (mi <= 2);
    int64_t era = floordiv(yy, 400);
    int64_t yoe = yy - era * 400;
    int64_t doy = (153 * (mi + (mi > 2 ? -3 : 9)) + 2) / 5 + di - 1;
    int64_t doe = yoe * 365 + yoe / 4 - yoe / 100 + doy;
    return era * 146097 + doe - 719468;
}

static double angle(Fields *F, int k) {  /* nmea._angle */
    double v = fnum(F, k, NULL);
    if (!isnan(v) && (v < 0 || v > 360)) {
        F->bad = 1;
        return NAN;
    }
    return (v >= 360.0 ? v - 360.0 : v) * DEG;
}

static double signed_angle(Fields *F, int k, int kh) {  /* nmea._signed */
    double v = fnum(F, k, NULL);
    int h = fchar(F, kh);
    if (!isnan(v) && h != 'E' && h != 'W' && h != 0) F->bad = 1;
    return (h == 'W' ? -v : v) * DEG;
}

static double speed(Fields *F, int k_kn, int k_kmh) {  /* nmea._speed */
    double v = fnum(F, k_kn, NULL) * KN_MPS;  /* knots -> m/s */
    if (k_kmh) {
        double kmh = fnum(F, k_kmh, NULL);
        if (isnan(v)) v = kmh / 3.6;  /* km/h -> m/s where knots are empty */
    }
    return v;
}

static int quality_fix(int st, int mode) {  /* GLL/RMC status + mode -> quality */
    return (st == 'A' && mode != 'N') ? 1 : (st == 0 ? -1 : 0);
}

typedef struct {
    int64_t tod, date;
    int dec, code;
    double v[NVAL];
} Row;

/* nmea._decode for one sentence; returns 0 if every field read is valid */
static int decode(int t, Fields *F, Row *r) {
    int i;
    r->tod = -1;
    r->date = -1;
    r->dec = -1;
    r->code = 0;
    for (i = 0; i < NVAL; i++) r->v[i] = NAN;
    switch (t) {
    case T_HDT: case T_HDM: case T_THS: {
        double h = angle(F, 1);
        int ref = fchar(F, 2);
        if (t == T_THS && ref == 'V') h = NAN;  /* mode V: not valid */
        r->v[0] = h;
        r->code = t == T_HDM ? 'M' : 'T';
        break;
    }
    case T_HDG:
        r->v[0] = angle(F, 1);
        r->v[1] = signed_angle(F, 2, 3);
        r->v[2] = signed_angle(F, 4, 5);
        r->code = 'M';
        break;
    case T_ROT: {
        double v = fnum(F, 1, NULL);
        if (fchar(F, 2) == 'V') v = NAN;  /* status V: not valid */
        r->v[0] = v * DEG / 60.0;  /* deg/min -> rad/s */
        break;
    }
    case T_VHW:
        r->v[0] = speed(F, 5, 7);
        break;
    case T_VBW: {
        double lw = fnum(F, 1, NULL), tw = fnum(F, 2, NULL);
        int sw = fchar(F, 3);
        double lg = fnum(F, 4, NULL), tg = fnum(F, 5, NULL);
        int sg = fchar(F, 6);
        r->v[0] = sw != 'V' ? lw * KN_MPS : NAN;
        r->v[1] = sw != 'V' ? tw * KN_MPS : NAN;
        r->v[2] = sg != 'V' ? lg * KN_MPS : NAN;
        r->v[3] = sg != 'V' ? tg * KN_MPS : NAN;
        break;
    }
    case T_VLW:
        r->v[0] = fnum(F, 1, NULL) * NMI_M;
        r->v[1] = fnum(F, 3, NULL) * NMI_M;
        break;
    case T_GGA: case T_GNS: {
        r->tod = tod(F, 1);
        r->v[0] = latlon(F, 2, 3, 'N', 'S', 90.0, &r->dec);
        r->v[1] = latlon(F, 4, 5, 'E', 'W', 180.0, &i);
        if (t == T_GGA) {
            double q = fnum(F, 6, NULL);
            if (isnan(q)) {
                r->code = -1;
            } else if (q > -129.0 && q < 128.0) {
                r->code = (int)q;  /* astype(int8): truncation */
            } else {
                F->bad = 1;  /* numpy's out-of-range cast: leave it to numpy */
            }
        } else {
            static const char modes[] = "NAPDRFEMS";
            static const int qv[] = {0, 1, 3, 2, 4, 5, 6, 7, 8};
            int mode = ffirst(F, 6);
            r->code = -1;
            for (i = 0; i < 9; i++)
                if (mode == modes[i]) r->code = qv[i];
        }
        r->v[3] = fnum(F, 8, NULL);  /* hdop */
        r->v[2] = fnum(F, 9, NULL);  /* alt */
        break;
    }
    case T_GLL: {
        r->v[0] = latlon(F, 1, 2, 'N', 'S', 90.0, &r->dec);
        r->v[1] = latlon(F, 3, 4, 'E', 'W', 180.0, &i);
        r->tod = tod(F, 5);
        int st = fchar(F, 6);
        int mode = fchar(F, 7);
        r->code = quality_fix(st, mode);
        break;
    }
    case T_RMC: {
        r->tod = tod(F, 1);
        int st = fchar(F, 2);
        r->v[0] = latlon(F, 3, 4, 'N', 'S', 90.0, &r->dec);
        r->v[1] = latlon(F, 5, 6, 'E', 'W', 180.0, &i);
        r->v[5] = speed(F, 7, 0);  /* sog */
        r->v[4] = angle(F, 8);     /* cog */
        double dv = fnum(F, 9, NULL);
        double dd = floor(dv / 10000.0);
        double mo = floor(dv / 100.0) - 100.0 * dd;
        double yy = dv - 10000.0 * dd - 100.0 * mo;
        double yyyy = yy >= 80 ? 1900.0 + yy : 2000.0 + yy;
        r->date = ymd_days(F, yyyy, mo, dd);
        int mode = fchar(F, 12);
        r->code = quality_fix(st, mode);
        if (r->code == 0) r->v[4] = r->v[5] = NAN;  /* status V / mode N: no valid velocity */
        break;
    }
    case T_VTG:
        r->v[0] = angle(F, 1);
        r->v[1] = speed(F, 5, 7);
        if (fchar(F, 9) == 'N') r->v[0] = r->v[1] = NAN;  /* mode N: data not valid */
        break;
    case T_ZDA: {
        r->tod = tod(F, 1);
        double d = fnum(F, 2, NULL), m = fnum(F, 3, NULL), y = fnum(F, 4, NULL);
        r->date = ymd_days(F, y, m, d);
        break;
    }
    }
    return F->bad;
}

typedef struct {
    Py_ssize_t off, len;
    Py_ssize_t first_line;
} Name;

typedef struct {
    Name names[MAXNAMES];
    int n;
} NameTable;

/* code of the name b[off, off+len) (len 0: no source), -1 if the table is full */
static int intern(NameTable *T, const uint8_t *b, Py_ssize_t off, Py_ssize_t len, Py_ssize_t line) {
    for (int i = 0; i < T->n; i++)
        if (T->names[i].len == len && memcmp(b + T->names[i].off, b + off, (size_t)len) == 0)
            return i;
    if (T->n == MAXNAMES) return -1;
    T->names[T->n] = (Name){off, len, line};
    return T->n++;
}

/* TAG block b[0, ln) ('\...*hh\').  Returns 0 if it is well formed with a correct
 * checksum (tagblock.parse_tag_rows), filling ext_ns and the source span. */
static int parse_tag(const uint8_t *b, Py_ssize_t ln, int64_t *ext, Py_ssize_t *ss, Py_ssize_t *sl) {
    Py_ssize_t j;
    const uint8_t *ps = memchr(b, '*', (size_t)ln);
    if (!ps) return -1;
    Py_ssize_t star = ps - b;
    Py_ssize_t cslen = ln - star - 2;
    if (b[ln - 1] != '\\' || (cslen != 1 && cslen != 2)) return -1;
    int hlo = hexval(b[ln - 2]);
    int hhi = cslen == 2 ? hexval(b[ln - 3]) : 0;
    if (hlo < 0 || hhi < 0) return -1;
    uint8_t x = 0;
    for (j = 1; j < star; j++) x ^= b[j];
    if (x != hhi * 16 + hlo) return -1;
    Py_ssize_t cs = -1, ce = 0, s0 = -1, se = 0;
    for (j = 2; j < star; j++) {
        if (b[j] != ':' || (b[j - 2] != ',' && b[j - 2] != '\\')) continue;
        int key = b[j - 1];
        if ((key != 'c' || cs >= 0) && (key != 's' || s0 >= 0)) continue;
        Py_ssize_t e = j + 1;
        while (e < star && b[e] != ',') e++;
        if (key == 'c') {
            cs = j + 1;
            ce = e;
        } else {
            s0 = j + 1;
            se = e;
        }
    }
    *ext = MISSING_NS;
    *ss = 0;
    *sl = 0;
    if (s0 >= 0) {
        if (se - s0 > MAX_SOURCE) return -1;
        *ss = s0;
        *sl = se - s0;
    }
    if (cs >= 0) {
        double v;
        int d;
        int r = parse_num(b + cs, ce - cs, &v, &d);
        if (r < 0) return -1;
        if (r == 1) {
            if (fabs(v < 1e10 ? v * 1e9 : v * 1e6) >= 9.2e18) return -1;
            double iv = floor(v);
            double fr = v - iv;
            int64_t whole = (int64_t)iv;
            int64_t us = (int64_t)nearbyint(fr * 1e6);
            *ext = v >= 1e10 ? whole * 1000000 + us : whole * 1000000000 + us * 1000;  /* ms or s */
        }
    }
    return 0;
}

typedef struct {
    /* input */
    const uint8_t *b;
    Py_ssize_t n;
    Py_ssize_t max_line;
    /* fallback lines (capacity cap_lines): their line index (8 bytes each, never per line) */
    int64_t *fb_line;
    Py_ssize_t cap_lines;
    /* lines too long (capacity cap_long): line index, content start, content end */
    int64_t *long_line, *long_start, *long_end;
    Py_ssize_t cap_long;
    /* side buffer (capacity n) */
    uint8_t *sub;
    /* per row (capacity cap_rows) */
    int64_t *r_line, *r_seq, *r_ext, *r_tod, *r_date;
    uint16_t *r_talker;
    int8_t *r_stype, *r_dec, *r_code;
    int32_t *r_src;
    double *r_val;
    Py_ssize_t cap_rows;
    /* output */
    Py_ssize_t n_lines, n_blank, n_rows, n_fb, n_long, sub_len, n_tag;
    int64_t n_seg;
    NameTable names;
    int overflow;
} Scan;

/* sentence starts in [ls, end) as numpy counts them: '$' or '!' not followed by another */
static Py_ssize_t count_segs(const Scan *S, Py_ssize_t ls, Py_ssize_t end) {
    const uint8_t *b = S->b;
    Py_ssize_t nseg = 0;
    for (Py_ssize_t j = ls; j < end; j++)
        if ((b[j] == '$' || b[j] == '!') && !(j + 1 < S->n && (b[j + 1] == '$' || b[j + 1] == '!')))
            nseg++;
    return nseg;
}

/* where the tail [from, end) of a line too long is read from (nmea._tail_start): its last
 * sentence start '$' or '!', with the TAG block just before it; end if it has none or if
 * that TAG block is longer than TAG_MAX (damaged: its source and time are unknown) */
static Py_ssize_t tail_start(const uint8_t *b, Py_ssize_t from, Py_ssize_t end) {
    Py_ssize_t j, k;
    for (j = end - 1; j >= from; j--)
        if (b[j] == '$' || b[j] == '!') break;
    if (j < from) return end;
    if (j > from && b[j - 1] == '\\') {  /* after a TAG block: with it, or not at all */
        for (k = j - 2; k >= from && k >= j - 1 - TAG_MAX; k--)
            if (b[k] == '\\') return k;
        return end;
    }
    return j;
}

/* one line, content [ls, end) (its line end excluded), index li, segments before it seg0 */
static int scan_line(Scan *S, Py_ssize_t ls, Py_ssize_t end, Py_ssize_t li, int64_t seg0,
                     Py_ssize_t *nseg_out) {
    const uint8_t *b = S->b;
    /* one branch-free pass (vectorised by the compiler): sentence starts, bytes outside
     * printable ASCII; the segment count is exact (doubled starts '$$' count once) */
    size_t nstart = 0;
    unsigned bad = 0;
    Py_ssize_t st = -1, j;
    for (j = ls; j < end; j++) {
        uint8_t c = b[j];
        bad |= (uint8_t)(c - 32) > 94;
        nstart += (c == '$') + (c == '!');
    }
    int comment = end > ls && b[ls] == '#';
    int printable = !bad;
    Py_ssize_t nseg = (Py_ssize_t)nstart;
    if (nstart > 1) {  /* several starts: count them as numpy does, for the seq numbers */
        nseg = count_segs(S, ls, end);
    } else if (nstart == 1) {
        const uint8_t *d = memchr(b + ls, '$', (size_t)(end - ls));
        st = d ? (Py_ssize_t)(d - b) : -1;
    }
    *nseg_out = comment ? 0 : nseg;
    if (end == ls) {  /* blank */
        if (intern(&S->names, b, 0, 0, li) < 0) return 1;
        S->n_blank++;
        return 0;
    }
    if (comment || !printable || nstart != 1 || st < 0) return 1;
    int64_t ext = MISSING_NS;
    Py_ssize_t ss = 0, sl = 0;
    int tagged = st > ls;
    if (tagged) {
        if (b[ls] != '\\' || st - ls > TAG_MAX) return 1;
        if (parse_tag(b + ls, st - ls, &ext, &ss, &sl)) return 1;
        ss += ls;
    }
    /* the sentence [st, end): '$' address, fields '*hh' */
    if (end - st < 4 || b[end - 3] != '*') return 1;
    int h1 = hexval(b[end - 2]), h2 = hexval(b[end - 1]);
    if (h1 < 0 || h2 < 0) return 1;
    Fields F;
    F.b = b;
    F.body_end = end - 3;
    F.nf = 0;
    F.bad = 0;
    uint8_t x = 0;
    for (j = st + 1; j < F.body_end; j++) x ^= b[j];
    if (x != h1 * 16 + h2) return 1;
    for (j = st + 1; j < F.body_end; j++) {
        if (b[j] == ',') {
            if (F.nf == MAXF) return 1;
            F.comma[F.nf++] = j;
        }
    }
    if (F.nf == 0 || F.comma[0] - st - 1 != 5) return 1;
    const uint8_t *a = b + st + 1;
    for (j = 0; j < 5; j++) {
        int up = a[j] >= 'A' && a[j] <= 'Z';
        if (!(up || (j < 2 && a[j] >= '0' && a[j] <= '9'))) return 1;
    }
    if (a[0] == 'P') return 1;  /* proprietary: numpy counts it */
    int t;
    for (t = 0; t < NTYPES; t++)
        if (memcmp(a + 2, TYPES[t], 3) == 0) break;
    if (t == NTYPES) return 1;
    if (t == T_HDG || t == T_HDM || t == T_VHW || t == T_VBW || t == T_VLW)
        for (j = 0; j < 8; j++)
            if (a[0] == GNSS[j][0] && a[1] == GNSS[j][1]) return 1;
    if (F.nf < FMIN[t] || F.nf > FMAX[t]) return 1;
    Row r;
    if (decode(t, &F, &r)) return 1;
    if (S->n_rows >= S->cap_rows) return 1;  /* cannot happen (rows <= '$' count): numpy reads it */
    int code = intern(&S->names, b, ss, sl, li);
    if (code < 0) return 1;
    Py_ssize_t k = S->n_rows++;
    S->r_line[k] = li + 1;
    S->r_seq[k] = seg0;
    S->r_talker[k] = (uint16_t)(a[0] | (a[1] << 8));
    S->r_stype[k] = (int8_t)t;
    S->r_src[k] = code;
    S->r_ext[k] = ext;
    S->r_tod[k] = r.tod;
    S->r_date[k] = r.date;
    S->r_dec[k] = (int8_t)r.dec;
    S->r_code[k] = (int8_t)r.code;
    memcpy(S->r_val + k * NVAL, r.v, sizeof r.v);
    S->n_tag += tagged;
    return 0;
}

static void scan_all(Scan *S) {
    Py_ssize_t ls = 0, li = 0;
    const Py_ssize_t n = S->n;
    int64_t seg = 0;
    const uint8_t *b = S->b;
    /* the next LF and the next CR at or after ls (n: none), each found once: a file with
     * one kind of line end costs one memchr of the other kind for the whole block */
    Py_ssize_t nlf = -1, ncr = -1;
    while (ls < n) {
        const uint8_t *p;
        if (nlf < ls) {
            p = memchr(b + ls, '\n', (size_t)(n - ls));
            nlf = p ? (Py_ssize_t)(p - b) : n;
        }
        if (ncr < ls) {
            p = memchr(b + ls, '\r', (size_t)(n - ls));
            ncr = p ? (Py_ssize_t)(p - b) : n;
        }
        Py_ssize_t end = nlf < ncr ? nlf : ncr;  /* content end: the first byte of the line end */
        Py_ssize_t next;
        if (end == n)
            next = n;  /* the last line, without a line end */
        else if (b[end] == '\n')
            next = end + 1;
        else if (end + 1 < n && b[end + 1] == '\n')
            next = end + 2;  /* CR LF */
        else if (end + 2 < n && b[end + 1] == '\r' && b[end + 2] == '\n')
            next = end + 3;  /* CR CR LF */
        else
            next = end + 1;  /* a lone CR */
        if (li >= S->cap_lines) {
            S->overflow = 1;
            return;
        }
        Py_ssize_t nseg = 0, from = ls;
        int fb;
        if (end - ls > S->max_line) {
            /* too long: listed (rejected as 'too_long'), not scanned; only its tail, from
             * its last sentence start (and TAG block) in its last max_line bytes, is copied
             * for the numpy path (a sentence written after a run of NUL bytes is read) */
            if (S->n_long >= S->cap_long) {
                S->overflow = 1;
                return;
            }
            S->long_line[S->n_long] = li;
            S->long_start[S->n_long] = ls;
            S->long_end[S->n_long] = end;
            S->n_long++;
            from = tail_start(b, end - S->max_line, end);
            fb = from < end;
            if (fb) nseg = count_segs(S, from, end);
        } else {
            fb = scan_line(S, ls, end, li, seg, &nseg);
        }
        if (fb) {
            memcpy(S->sub + S->sub_len, b + from, (size_t)(next - from));
            S->sub_len += next - from;
            S->fb_line[S->n_fb++] = li;
        }
        seg += nseg;
        li++;
        ls = next;
    }
    S->n_lines = li;
    S->n_seg = seg;
}

static int get_w(PyObject *o, Py_buffer *v, Py_ssize_t min_bytes, const char *what) {
    if (PyObject_GetBuffer(o, v, PyBUF_WRITABLE | PyBUF_C_CONTIGUOUS) < 0) return -1;
    if (v->len < min_bytes) {
        PyErr_Format(PyExc_ValueError, "_nmeascan.scan: %s holds %zd bytes, needs %zd",
                     what, v->len, min_bytes);
        PyBuffer_Release(v);
        return -1;
    }
    return 0;
}

PyDoc_STRVAR(scan_doc,
"scan(data, cap_lines, cap_rows, max_line, fb_line, long_line, long_start, long_end, sub,\n"
"     r_line, r_seq, r_talker, r_stype, r_src, r_ext, r_tod, r_date, r_dec, r_code, r_val)\n"
"-> (n_lines, n_blank, n_rows, n_fb, n_long, sub_len, n_seg, n_tag, names, names_first_line)\n\n"
"Scan a block of NMEA text into the given writable arrays (see nmea._scan_c).");

#define NARR 16

static PyObject *scan(PyObject *self, PyObject *args) {
    PyObject *o[NARR + 1];
    Py_ssize_t cap, cap_rows, max_line;
    if (!PyArg_ParseTuple(args, "OnnnOOOOOOOOOOOOOOOO", &o[0], &cap, &cap_rows, &max_line,
                          &o[1], &o[2], &o[3], &o[4], &o[5], &o[6], &o[7], &o[8], &o[9],
                          &o[10], &o[11], &o[12], &o[13], &o[14], &o[15], &o[16]))
        return NULL;
    if (cap < 1 || cap_rows < 0 || max_line < 0) {
        PyErr_SetString(PyExc_ValueError,
                        "_nmeascan.scan: cap_lines must be >= 1, cap_rows and max_line >= 0");
        return NULL;
    }
    Py_buffer in, v[NARR];
    int nv = 0;
    if (PyObject_GetBuffer(o[0], &in, PyBUF_C_CONTIGUOUS) < 0) return NULL;
    static const char *what[NARR] = {"fb_line", "long_line", "long_start", "long_end", "sub",
                                     "r_line", "r_seq", "r_talker", "r_stype", "r_src", "r_ext",
                                     "r_tod", "r_date", "r_dec", "r_code", "r_val"};
    /* bytes per line (0), per long line (1-3), the side buffer (4), per row (5-15) */
    const Py_ssize_t per[NARR] = {8, 8, 8, 8, 0, 8, 8, 2, 1, 4, 8, 8, 8, 1, 1, 8 * NVAL};
    const Py_ssize_t cap_long = in.len / (max_line + 1) + 1;  /* each holds > max_line bytes */
    PyObject *res = NULL;
    for (nv = 0; nv < NARR; nv++) {
        Py_ssize_t need = nv < 1 ? per[nv] * cap : nv < 4 ? per[nv] * cap_long
                          : nv == 4 ? in.len : per[nv] * cap_rows;
        if (get_w(o[nv + 1], &v[nv], need, what[nv]) < 0) goto done;
    }
    Scan *S = PyMem_Calloc(1, sizeof(Scan));
    if (!S) {
        PyErr_NoMemory();
        goto done;
    }
    S->b = in.buf;
    S->n = in.len;
    S->max_line = max_line;
    S->cap_lines = cap;
    S->cap_long = cap_long;
    S->cap_rows = cap_rows;
    S->fb_line = v[0].buf;
    S->long_line = v[1].buf;
    S->long_start = v[2].buf;
    S->long_end = v[3].buf;
    S->sub = v[4].buf;
    S->r_line = v[5].buf;
    S->r_seq = v[6].buf;
    S->r_talker = v[7].buf;
    S->r_stype = v[8].buf;
    S->r_src = v[9].buf;
    S->r_ext = v[10].buf;
    S->r_tod = v[11].buf;
    S->r_date = v[12].buf;
    S->r_dec = v[13].buf;
    S->r_code = v[14].buf;
    S->r_val = v[15].buf;
    Py_BEGIN_ALLOW_THREADS
    scan_all(S);
    Py_END_ALLOW_THREADS
    if (S->overflow) {
        PyErr_SetString(PyExc_ValueError, "_nmeascan.scan: more lines than cap_lines");
    } else {
        PyObject *names = PyList_New(S->names.n), *first = PyList_New(S->names.n);
        if (names && first) {
            for (int i = 0; i < S->names.n; i++) {
                Name *nm = &S->names.names[i];
                PyList_SET_ITEM(names, i, PyUnicode_DecodeASCII((const char *)S->b + nm->off,
                                                                 nm->len, "strict"));
                PyList_SET_ITEM(first, i, PyLong_FromSsize_t(nm->first_line));
            }
            if (!PyErr_Occurred())
                res = Py_BuildValue("nnnnnnLnOO", S->n_lines, S->n_blank, S->n_rows, S->n_fb,
                                    S->n_long, S->sub_len, (long long)S->n_seg, S->n_tag, names,
                                    first);
        }
        Py_XDECREF(names);
        Py_XDECREF(first);
    }
    PyMem_Free(S);
done:
    for (int i = 0; i < nv; i++) PyBuffer_Release(&v[i]);
    PyBuffer_Release(&in);
    return res;
}

PyDoc_STRVAR(sizes_doc,
"sizes(data) -> (cap_lines, cap_rows)\n\n"
"Upper bounds for scan(): lines (each ends at an LF or at a CR not followed by an LF, the\n"
"last one may have no end) and rows (each decoded sentence has its own '$').  One pass.");

static PyObject *sizes(PyObject *self, PyObject *arg) {
    Py_buffer in;
    if (PyObject_GetBuffer(arg, &in, PyBUF_C_CONTIGUOUS) < 0) return NULL;
    const uint8_t *b = in.buf;
    const Py_ssize_t n = in.len;
    size_t lf = 0, cr = 0, dollar = 0;
    Py_ssize_t i;
    Py_BEGIN_ALLOW_THREADS
    for (i = 0; i + 1 < n; i++) {  /* branch-free: vectorised by the compiler */
        uint8_t c = b[i];
        lf += c == '\n';
        cr += (c == '\r') & (b[i + 1] != '\n');
        dollar += c == '$';
    }
    if (n > 0) {
        lf += b[n - 1] == '\n';
        cr += b[n - 1] == '\r';
        dollar += b[n - 1] == '$';
    }
    Py_END_ALLOW_THREADS
    PyBuffer_Release(&in);
    size_t lines = lf + cr + 1;
    return Py_BuildValue("nn", (Py_ssize_t)lines, (Py_ssize_t)(dollar < lines ? dollar : lines));
}

static PyMethodDef methods[] = {
    {"scan", scan, METH_VARARGS, scan_doc},
    {"sizes", sizes, METH_O, sizes_doc},
    {NULL, NULL, 0, NULL},
};

static struct PyModuleDef module = {
    PyModuleDef_HEAD_INIT, "_nmeascan",
    "Compiled one-pass scanner for NMEA 0183 blocks (see dracc.ingest.nmea).", -1, methods,
};

PyMODINIT_FUNC PyInit__nmeascan(void) {
    PyObject *m = PyModule_Create(&module);
    if (m && PyModule_AddIntConstant(m, "NVAL", NVAL) < 0) {
        Py_DECREF(m);
        return NULL;
    }
    return m;
}
