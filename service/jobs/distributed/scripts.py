"""The Lua scripts of :mod:`service.jobs.distributed.store`: every state change of a job record is
one
atomic script, conditional on the expected status and fields (key names are built in the
scripts from the prefix: one Redis, not a cluster).
"""

from __future__ import annotations

__all__ = ["CLAIM", "CLAIM_WEBHOOK", "DELETE", "UPDATE"]

# Moves a job between the status indexes (all jobs, and its tenant's) and the lease/finish sets.
_MOVE = """
local function move(p, key, id, old, new, now)
  local seq = redis.call('HGET', key, 'seq')
  local tenant = redis.call('HGET', key, 'tenant')
  redis.call('HSET', key, 'status', new)
  redis.call('ZREM', p .. ':idx:*:' .. old, id)
  redis.call('ZADD', p .. ':idx:*:' .. new, seq, id)
  if tenant then
    redis.call('ZREM', p .. ':idx:t' .. tenant .. ':' .. old, id)
    redis.call('ZADD', p .. ':idx:t' .. tenant .. ':' .. new, seq, id)
  end
  if new ~= 'running' then redis.call('ZREM', p .. ':leases', id) end
  if new == 'succeeded' or new == 'failed' or new == 'cancelled' then
    redis.call('ZADD', p .. ':finished', now, id)
    redis.call('HINCRBY', p .. ':stats:finished', new, 1)
    if redis.call('HGET', key, 'webhook_url') then
      redis.call('ZADD', p .. ':webhooks', now, id)
    end
  end
end
"""

# ARGV: prefix, id, expected statuses (csv, '' any), new status ('' unchanged), now,
# nc, (field, value) * nc conditions, ns, (field, value) * ns sets; a value NUL means "absent"
# (condition) or "delete" (set). Returns the status before the call, 0 when a condition failed,
# -1 for an unknown job.
UPDATE = _MOVE + """
local p, id = ARGV[1], ARGV[2]
local key = p .. ':job:' .. id
local st = redis.call('HGET', key, 'status')
if not st then return -1 end
if ARGV[3] ~= '' then
  local ok = false
  for s in string.gmatch(ARGV[3], '[^,]+') do if s == st then ok = true end end
  if not ok then return 0 end
end
local now = ARGV[5]
local nc = tonumber(ARGV[6])
for i = 0, nc - 1 do
  local f, v = ARGV[7 + 2 * i], ARGV[8 + 2 * i]
  local cur = redis.call('HGET', key, f)
  if v == '\\0' then
    if cur then return 0 end
  elseif cur ~= v then return 0 end
end
local base = 7 + 2 * nc
for i = 0, tonumber(ARGV[base]) - 1 do
  local f, v = ARGV[base + 1 + 2 * i], ARGV[base + 2 + 2 * i]
  if v == '\\0' then redis.call('HDEL', key, f) else redis.call('HSET', key, f, v) end
end
redis.call('HSET', key, 'updated_at', now)
local new = ARGV[4]
if new ~= '' and new ~= st then move(p, key, id, st, new, now) end
local cur = redis.call('HGET', key, 'status')
local lease = redis.call('HGET', key, 'lease_until')
if cur == 'running' and lease then redis.call('ZADD', p .. ':leases', lease, id) end
if cur == 'queued' and not redis.call('HGET', key, 'rq_job') then
  redis.call('ZADD', p .. ':pending', redis.call('HGET', key, 'not_before') or now, id)
else
  redis.call('ZREM', p .. ':pending', id)
end
return st
"""

# ARGV: prefix, id, owner, now, lease_until, pid, host, progress, rq job. Returns the attempt,
# or 0 when the job is not queued for this very RQ job (cancelled, or a stale duplicate).
CLAIM = _MOVE + """
local p, id = ARGV[1], ARGV[2]
local key = p .. ':job:' .. id
if redis.call('HGET', key, 'status') ~= 'queued' then return 0 end
if redis.call('HGET', key, 'rq_job') ~= ARGV[9] then return 0 end
local attempt = redis.call('HINCRBY', key, 'attempts', 1)
redis.call('HSET', key, 'owner', ARGV[3], 'started_at', ARGV[4], 'updated_at', ARGV[4],
           'lease_until', ARGV[5], 'pid', ARGV[6], 'host', ARGV[7], 'progress', ARGV[8])
move(p, key, id, 'queued', 'running', ARGV[4])
redis.call('ZADD', p .. ':leases', ARGV[5], id)
return attempt
"""

# ARGV: prefix, id. Deletes a finished job; returns 1, or 0 when not finished / unknown.
DELETE = """
local p, id = ARGV[1], ARGV[2]
local key = p .. ':job:' .. id
local st = redis.call('HGET', key, 'status')
if st ~= 'succeeded' and st ~= 'failed' and st ~= 'cancelled' then return 0 end
local tenant = redis.call('HGET', key, 'tenant')
local idem = redis.call('HGET', key, 'idem')
redis.call('ZREM', p .. ':idx:*:*', id)
redis.call('ZREM', p .. ':idx:*:' .. st, id)
if tenant then
  redis.call('ZREM', p .. ':idx:t' .. tenant .. ':*', id)
  redis.call('ZREM', p .. ':idx:t' .. tenant .. ':' .. st, id)
end
if idem then redis.call('DEL', idem) end
redis.call('ZREM', p .. ':finished', id)
redis.call('ZREM', p .. ':webhooks', id)
redis.call('DEL', key)
return 1
"""

# ARGV: prefix, id, now, stale_before. Takes a finished job's webhook delivery; 1 or 0.
CLAIM_WEBHOOK = """
local key = ARGV[1] .. ':job:' .. ARGV[2]
local st = redis.call('HGET', key, 'status')
if st ~= 'succeeded' and st ~= 'failed' and st ~= 'cancelled' then return 0 end
if not redis.call('HGET', key, 'webhook_url') then return 0 end
local state = redis.call('HGET', key, 'webhook_state')
if state then
  if string.sub(state, 1, 8) ~= 'sending:' then return 0 end
  if tonumber(string.sub(state, 9)) >= tonumber(ARGV[4]) then return 0 end
end
redis.call('HSET', key, 'webhook_state', 'sending:' .. ARGV[3])
redis.call('ZADD', ARGV[1] .. ':webhooks', ARGV[3], ARGV[2])
return 1
"""
